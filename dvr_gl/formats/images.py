"""Saving images: :func:`save_png` writes a premultiplied float RGBA image (conventions
section 7) atomically, as :func:`to_png_array` turns it into 8 bits."""

from __future__ import annotations

import io
import os

import numpy as np

from ..util.files import atomic_write
from .errors import InputError, MissingFileError
from .parsing import _triplet


def to_png_array(image, background=None):
    """The 8-bit array :func:`save_png` writes: (H, W, 4) un-premultiplied RGBA, or
    (H, W, 3) RGB composited over ``background``.

    ``image`` is (H, W, 4) float premultiplied RGBA (conventions section 7), clipped to
    [0, 1]. Without a background the colour is ``C / A`` (0 where the 8-bit alpha is 0);
    with ``background = (r, g, b)`` in [0, 1] the pixel is ``C + (1 - A) * B``. Rounded to
    the nearest of 256 levels.
    """
    if not isinstance(image, np.ndarray):
        raise InputError("image", f"expected a numpy array (H, W, 4), got {type(image).__name__}")
    if image.ndim != 3 or image.shape[2] != 4 or image.shape[0] < 1 or image.shape[1] < 1:
        raise InputError("image", f"expected shape (H, W, 4) premultiplied RGBA, got {image.shape}")
    if image.dtype.kind != "f":
        raise InputError("image", f"expected floats in [0, 1], got dtype {image.dtype}")
    bg = None
    if background is not None:
        bg = np.array(_triplet(background, "background"), dtype=np.float64)
        if np.any(bg < 0) or np.any(bg > 1):
            raise InputError("background", f"components must lie in [0, 1], got {tuple(bg.tolist())}")
    height, width = image.shape[:2]
    out = np.empty((height, width, 4 if bg is None else 3), np.uint8)
    rows = max(1, (1 << 22) // (width * 4))  # float64 work in blocks of ~32 MiB: posters fit in memory
    for start in range(0, height, rows):
        block = image[start:start + rows]
        if not np.isfinite(block).all():
            idx = tuple(int(i) for i in np.argwhere(~np.isfinite(block))[0])
            idx = (idx[0] + start,) + idx[1:]
            raise InputError("image", f"has non-finite values (first at (row, col, channel) {idx}: {image[idx]!r})")
        out[start:start + rows] = _png_block(np.clip(block.astype(np.float64), 0.0, 1.0), bg)
    return out


def _png_block(img, bg):
    colour, alpha = img[..., :3], img[..., 3:]
    if bg is None:
        alpha8 = np.rint(alpha * 255)
        with np.errstate(divide="ignore", invalid="ignore"):
            straight = np.where(alpha > 0, colour / alpha, 0.0)
        rgb8 = np.rint(np.clip(straight, 0.0, 1.0) * 255)
        rgb8[np.broadcast_to(alpha8 == 0, rgb8.shape)] = 0
        return np.concatenate([rgb8, alpha8], axis=-1)
    return np.rint(np.clip(colour + (1.0 - alpha) * bg, 0.0, 1.0) * 255)


def save_png(path, image, background=None):
    """Write ``image`` ((H, W, 4) float premultiplied RGBA, row 0 on top) to ``path``.

    Without ``background`` the PNG is un-premultiplied RGBA (colour 0 where alpha is 0);
    with ``background = (r, g, b)`` in [0, 1] it is RGB, ``C + (1 - A) * B``. 8 bits per
    channel, rounded (see :func:`to_png_array`). The write is atomic: the PNG is written to
    a temporary file in the same directory and renamed over ``path``, so ``path`` is
    either untouched or complete, and nothing is left behind on an error. Returns
    ``path``.
    """
    from PIL import Image

    try:
        path = os.fspath(path)
    except TypeError:
        raise InputError("path", f"expected a file name, got {path!r}") from None
    pixels = to_png_array(image, background)  # validate before touching the disk
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise MissingFileError("path", f"the directory {directory!r} of {path!r} does not exist")
    if os.path.isdir(path):
        raise InputError("path", f"{path!r} is a directory")
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="PNG")
    atomic_write(path, buffer.getvalue())
    return path
