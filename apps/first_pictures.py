"""Render every volume and mesh file of the shared data folder with ``dvr-gl render FILE
-o OUT.png`` and no other option, then lay the pictures out in one contact sheet.

    python apps/first_pictures.py [DATA_DIR] [--out docs/first_pictures.png]

DATA_DIR defaults to $DVR_GL_DATA or the ``shared/data`` folder beside the checkout.
Headerless raw files are shown where their name carries shape and type in the Open SciVis
convention (``LIDC2_256x256x133_uint8.raw.gz``: ``dvr-gl render`` opens it with no
option); other headerless ``.raw.gz`` and the PLOT3D ``.bin`` files are left out (they
need their shape and type given), and so is a MetaImage's or a sliced NRRD's data. No
option is given, ``--orientation`` included: files without an anatomical orientation
keep the oblique view of their own axes. Prints each file's exit status and time.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

from PIL import Image, ImageDraw

from dvr_gl.frontends import cli
from dvr_gl.bench.common import DEFAULT_DATA_DIR
from dvr_gl.formats import raw_name_layout

SKIP_SUFFIXES = (".raw.gz", ".bin", ".json", ".md")


def data_files(root):
    """The files `dvr-gl render` can open with no option, one per picture."""
    out = []
    for folder in sorted(os.listdir(root)):
        path = os.path.join(root, folder)
        if not os.path.isdir(path):
            continue
        names = sorted(os.listdir(path))
        for name in names:
            lower = name.lower()
            if (lower.endswith(SKIP_SUFFIXES) and raw_name_layout(name) is None) or lower.startswith("readme"):
                continue      # a name_XxYxZ_dtype.raw.gz opens with no option: it stays
            if lower.startswith("quarter.") and not lower.endswith(".nhdr"):
                continue      # the slices of quarter.nhdr
            if lower.endswith(".raw") and os.path.splitext(name)[0] + ".mhd" in names:
                continue      # a MetaImage's data file
            out.append(os.path.join(path, name))
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data_dir", nargs="?", default=os.environ.get("DVR_GL_DATA", DEFAULT_DATA_DIR))
    parser.add_argument("--out", default=os.path.join("docs", "first_pictures.png"))
    parser.add_argument("--tile", type=int, default=256, help="side of each picture on the sheet (pixels)")
    args = parser.parse_args(argv)
    tiles, failures = [], 0
    with tempfile.TemporaryDirectory() as tmp:
        for path in data_files(args.data_dir):
            out = os.path.join(tmp, "picture.png")
            t0 = time.perf_counter()
            code = cli.main(["render", path, "-o", out])
            print(f"{code}  {time.perf_counter() - t0:6.1f} s  {path}", flush=True)
            if code != 0:
                failures += 1
                continue
            with Image.open(out) as im:
                picture = Image.new("RGBA", im.size, (255, 255, 255, 255))
                picture.alpha_composite(im.convert("RGBA"))
            picture = picture.convert("RGB").resize((args.tile, args.tile), Image.LANCZOS)
            ImageDraw.Draw(picture).text((4, 4), os.path.basename(path), fill=(0, 0, 0))
            tiles.append(picture)
    columns = 5
    rows = (len(tiles) + columns - 1) // columns
    sheet = Image.new("RGB", (columns * args.tile, rows * args.tile), "white")
    for i, picture in enumerate(tiles):
        sheet.paste(picture, ((i % columns) * args.tile, (i // columns) * args.tile))
    from dvr_gl.formats import atomic_write
    import io
    buffer = io.BytesIO()
    sheet.save(buffer, format="PNG", optimize=True)
    atomic_write(args.out, buffer.getvalue())
    print(f"wrote {args.out}: {len(tiles)} pictures, {failures} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
