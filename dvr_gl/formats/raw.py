"""Raw samples (``.raw``, ``.raw.gz``, ``.bin``, ``.dat``, no extension): bare samples, x
fastest, laid out by the shape and dtype given or by a name in the Open SciVis convention
``name_XxYxZ_dtype.raw``; a name ending in ``.gz`` is gunzipped first."""

from __future__ import annotations

import gzip
import os
import re
import zlib

import numpy as np

from .errors import InputError, MissingFileError, _named_errors


_RAW_EXTENSIONS = (".raw", ".raw.gz", ".bin", ".dat", ".gz")
_RAW_NAME = re.compile(r"_(\d+)x(\d+)x(\d+)_(uint8|int8|uint16|int16|uint32|int32|float32|float64)"
                       r"\.raw(\.gz)?$", re.IGNORECASE)


def raw_name_layout(path):
    """((nz, ny, nx), dtype) from a name in the Open SciVis convention
    ``name_XxYxZ_dtype.raw[.gz]`` (little-endian samples, x fastest), or None."""
    m = _RAW_NAME.search(os.path.basename(os.fspath(path)))
    if m is None:
        return None
    x, y, z = (int(v) for v in m.groups()[:3])
    return (z, y, x), np.dtype(m.group(4).lower()).newbyteorder("<")


def _is_raw_name(path):
    name = os.path.basename(path).lower()
    stem, ext = os.path.splitext(name)
    return name.endswith(_RAW_EXTENSIONS) or ext == "" or ext[1:].isdigit()


def _read_bytes(path, field="path"):
    try:
        if path.lower().endswith(".gz"):
            with gzip.open(path, "rb") as f:
                return f.read()
        with open(path, "rb") as f:
            return f.read()
    except FileNotFoundError:
        raise MissingFileError(field, f"no such file {path!r}") from None
    except (OSError, EOFError, zlib.error) as e:
        raise InputError(field, f"cannot read {path!r}: {e}") from None


@_named_errors
def _load_raw(path, shape, dtype):
    raw = _read_bytes(path)
    need = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if len(raw) != need:
        what = "gunzipped " if path.lower().endswith(".gz") else ""
        hint = ""
        if len(raw) > need:
            hint = f" ({len(raw) - need} bytes too many: a header? this reader expects bare samples)"
        raise InputError("shape", f"{what}file {path!r} holds {len(raw)} bytes, but shape {shape} (nz,ny,nx) "
                                  f"of {dtype.name} needs {need}{hint}")
    return np.frombuffer(raw, dtype=dtype).reshape(shape)
