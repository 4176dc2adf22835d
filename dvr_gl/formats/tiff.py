"""Multi-page TIFF stacks (``.tif`` / ``.tiff``) through tifffile, one page per slice."""

from __future__ import annotations

import numpy as np

from .errors import InputError, _named_errors, _optional


@_named_errors
def _load_tiff(path):
    """(data (nz, ny, nx), spacing) of a multi-page TIFF stack, through tifffile: one page
    per slice; x and y spacing from the resolution tags (1 / pixels per unit) and z from
    ImageJ's ``spacing``, each 1 where the file says nothing."""
    tifffile = _optional("tifffile", f"the TIFF stack {path!r}")
    with tifffile.TiffFile(path) as tif:
        data = tif.asarray()
        page = tif.pages[0]
        spacing = [1.0, 1.0, 1.0]
        for axis, tag in ((0, "XResolution"), (1, "YResolution")):
            if tag in page.tags:
                num, den = page.tags[tag].value
                if num > 0 and den > 0 and not (num == 1 and den == 1):
                    spacing[axis] = den / num
        meta = tif.imagej_metadata or {}
        if float(meta.get("spacing", 0) or 0) > 0:
            spacing[2] = float(meta["spacing"])
    if data.ndim != 3:
        raise InputError("path", f"{path!r} holds an image of shape {data.shape}; a TIFF stack for a volume "
                                 "has one grey page per slice (pages, rows, columns)")
    return np.ascontiguousarray(data), tuple(spacing)
