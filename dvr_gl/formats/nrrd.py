"""NRRD (``.nrrd`` / ``.nhdr``) through pynrrd, attached or detached, including the
multi-file forms of ``data file:`` that pynrrd does not read itself; spacing, origin,
orientation and modality from the header."""

from __future__ import annotations

import os
import re
import warnings
import zlib

import numpy as np

from .anatomy import _Assumed, _direction_codes, _modality_code
from .errors import InputError, MissingFileError, _named_errors


_FORMAT_RE = re.compile(r"%[-+ 0#]*\d*d")


def _nrrd_lines(path):
    """The header lines (magic included) up to the blank line that ends it (or EOF)."""
    lines = []
    with open(path, "rb") as f:
        for raw in f:
            line = raw.decode("latin-1").rstrip("\r\n")
            if not line.strip():
                break
            lines.append(line)
            if len(lines) > 100000:
                raise InputError("path", f"{path!r}: NRRD header has no end")
    if not lines or not lines[0].startswith("NRRD"):
        raise InputError("path", f"{path!r} is not a NRRD file (it does not start with 'NRRD')")
    return lines


@_named_errors
def _load_nrrd(path):
    import nrrd

    lines = _nrrd_lines(path)
    file_list = None
    for i, line in enumerate(lines):
        key, _, value = line.partition(":")
        if line.startswith("#") or value.startswith("="):
            continue
        if key.strip().lower() in ("data file", "datafile") and value.strip().split()[:1] == ["LIST"]:
            file_list = [ln.strip() for ln in lines[i + 1:] if ln.strip()]
            lines = lines[:i + 1]
            break
    try:
        header = nrrd.read_header(lines)
    except (nrrd.NRRDError, ValueError, KeyError) as e:
        raise InputError("path", f"{path!r}: bad NRRD header: {e}") from None
    for field in ("dimension", "type", "encoding", "sizes"):
        if field not in header:
            raise InputError(field, f"{path!r}: the NRRD header lacks the required field {field!r}")
    dim = int(header["dimension"])
    sizes = [int(s) for s in np.atleast_1d(header["sizes"])]
    if len(sizes) != dim:
        raise InputError("sizes", f"{path!r}: dimension is {dim} but sizes has {len(sizes)} values: {sizes}")
    if dim != 3:
        raise InputError("dimension", f"{path!r} is {dim}-D (sizes {sizes}); a volume is 3-D")
    known = getattr(getattr(nrrd, "reader", None), "_TYPEMAP_NRRD2NUMPY", None)
    if header["type"] == "block" or (known is not None and header["type"] not in known):
        raise InputError("type", f"{path!r}: unsupported NRRD type {header['type']!r}")
    if header["encoding"] not in ("raw", "ascii", "text", "txt", "gzip", "gz", "bzip2", "bz2"):
        raise InputError("encoding", f"{path!r}: unsupported NRRD encoding {header['encoding']!r} "
                                     "(raw, ascii, gzip and bzip2 are)")
    if np.dtype(known[header["type"]] if known else "u1").itemsize > 1 and \
            header["encoding"] not in ("ascii", "text", "txt") and header.get("endian") not in ("little", "big"):
        raise InputError("endian", f"{path!r}: multi-byte {header['type']!r} needs 'endian: little' or "
                                   f"'endian: big', got {header.get('endian')!r}")

    spec_key = "data file" if "data file" in header else ("datafile" if "datafile" in header else None)
    spec = header.get(spec_key) if spec_key else None
    try:
        if file_list is not None:
            parts = spec.split()
            subdim = _subdim(parts[1:], dim, path, spec)
            data = _read_nrrd_pieces(header, file_list, subdim, sizes, path)
        elif spec is not None and _is_format_spec(spec):
            parts = spec.split()
            fmt, (lo, hi, step) = parts[0], _ints(parts[1:4], path, spec)
            subdim = _subdim(parts[4:], dim, path, spec)
            if step == 0:
                raise InputError("data file", f"{path!r}: file number step must not be 0 in {spec!r}")
            if (hi - lo) * step < 0:
                raise InputError("data file", f"{path!r}: file number max {hi} is not reached from min {lo} "
                                              f"by step {step} in {spec!r}")
            try:
                names = [fmt % i for i in range(lo, hi + (1 if step > 0 else -1), step)]
            except (TypeError, ValueError) as e:
                raise InputError("data file", f"{path!r}: bad file name format {fmt!r}: {e}") from None
            data = _read_nrrd_pieces(header, names, subdim, sizes, path)
        elif spec is not None:  # one detached data file
            data = _read_nrrd_pieces(header, [spec], dim, sizes, path)
        else:  # attached: the data follows the header
            data, _ = nrrd.read(path, index_order="C")
    except nrrd.NRRDError as e:
        raise _nrrd_error(e, "sizes", f"{path!r}", f"sizes {sizes} need") from None
    except (OSError, EOFError, zlib.error) as e:
        if isinstance(e, InputError):
            raise
        raise InputError("path", f"cannot read the data of {path!r}: {e}") from None
    except ValueError as e:  # numpy reshape / frombuffer on a short or long file
        if isinstance(e, InputError):
            raise
        raise InputError("sizes", f"{path!r}: the data does not match sizes {sizes} "
                                  f"of {header['type']}: {e}") from None
    spacing, origin = _nrrd_geometry(header, path)
    modality = next((v for k, v in header.items() if str(k).strip().lower() == "modality"), None)
    return data, spacing, origin, _nrrd_orientation(header), _modality_code(modality)


def _is_format_spec(spec):
    parts = spec.split()
    if len(parts) not in (4, 5) or not _FORMAT_RE.search(parts[0].replace("%%", "")):
        return False
    return all(re.fullmatch(r"[-+]?\d+", p) for p in parts[1:])


def _ints(parts, path, spec):
    try:
        return tuple(int(p) for p in parts)
    except ValueError:
        raise InputError("data file", f"{path!r}: expected integers in {spec!r}") from None


def _subdim(parts, dim, path, spec):
    if not parts:
        return dim - 1
    if len(parts) != 1:
        raise InputError("data file", f"{path!r}: cannot parse {spec!r}")
    (subdim,) = _ints(parts, path, spec)
    if not 1 <= subdim <= dim:
        raise InputError("data file", f"{path!r}: data file dimension {subdim} is outside [1, {dim}] in {spec!r}")
    return subdim


def _read_nrrd_pieces(header, names, subdim, sizes, path):
    """Read a NRRD whose data is split over several files, each holding a ``subdim``-D
    piece (the fastest ``subdim`` axes; for ``subdim == dim``, equal slabs of the slowest
    axis), through pynrrd's per-file reader (encodings, skips and endianness)."""
    import nrrd

    dim = len(sizes)
    if not names:
        raise InputError("data file", f"{path!r}: the data file list is empty")
    if subdim < dim:
        piece = sizes[:subdim]
        count = int(np.prod(sizes[subdim:], dtype=np.int64))
        if count != len(names):
            raise InputError("data file", f"{path!r} names {len(names)} data files, but sizes {sizes} split into "
                                          f"{subdim}-D pieces need {count}")
    else:
        if sizes[-1] % len(names):
            raise InputError("data file", f"{path!r} names {len(names)} data files, which do not split the "
                                          f"{sizes[-1]} slices of the slowest axis evenly")
        piece = sizes[:-1] + [sizes[-1] // len(names)]
    base = os.path.dirname(path)
    chunks = []
    for name in names:
        target = name if os.path.isabs(name) else os.path.join(base, name)
        if not os.path.exists(target):
            raise MissingFileError("data file", f"{path!r} names the data file {name!r}, which does not exist "
                                                f"({target!r})")
        h = {k: v for k, v in header.items() if k not in ("data file", "datafile")}
        h["dimension"] = len(piece)
        h["sizes"] = np.array(piece)
        h["data file"] = os.path.abspath(target)
        try:
            chunk = nrrd.read_data(h, filename=path, index_order="C")
        except nrrd.NRRDError as e:
            need = "sizes {} need".format(sizes) if len(names) == 1 else \
                f"sizes {sizes} in {len(names)} files need per file"
            raise _nrrd_error(e, "data file", f"{path!r}: data file {name!r}", need) from None
        chunks.append(chunk.reshape(-1))
    return np.concatenate(chunks).reshape(tuple(sizes[::-1]))


def _nrrd_error(exc, field, where, need):
    """pynrrd's error as an InputError; its size mismatch ("...: 72-60=12") spelled out."""
    m = re.search(r"dimensions: (\d+)-(\d+)=", str(exc))
    if m:
        return InputError(field, f"{where} holds {m.group(2)} samples, but {need} {m.group(1)}")
    return InputError(field, f"{where}: {exc}")


_NRRD_SPACES = {"right-anterior-superior": "RAS", "ras": "RAS", "left-anterior-superior": "LAS", "las": "LAS",
                "left-posterior-superior": "LPS", "lps": "LPS"}

#: NRRD's non-anatomical 3-D spaces, read the way DICOM lays out a slice (columns towards
#: the patient's left, rows towards the back), the third axis then fixed by the space's
#: handedness: right-handed is LPS, left-handed LPI (VTK's CT head ``quarter.nhdr``, whose
#: slices run from the crown down, says ``3D-left-handed``)
_NRRD_CONVENTIONS = {"3d-right-handed": "LPS", "3d-right-handed-time": "LPS",
                     "3d-left-handed": "LPI", "3d-left-handed-time": "LPI"}


def _nrrd_orientation(header):
    """Where the index axes point anatomically (e.g. "RAS"), from an anatomical ``space``
    and the ``space directions`` (each axis named by its vector's largest component, with
    its sign). A ``3D-right-handed`` or ``3D-left-handed`` space gives the convention of
    ``_NRRD_CONVENTIONS``, marked as assumed; other spaces give None."""
    name = str(header.get("space", "")).lower()
    space = _NRRD_SPACES.get(name)
    if space is None and name in _NRRD_CONVENTIONS:
        directions = header.get("space directions")
        try:
            d = np.eye(3) if directions is None else np.array(directions, dtype=np.float64)
        except (TypeError, ValueError):
            return None
        codes = _direction_codes(d, _NRRD_CONVENTIONS[name])
        return None if codes is None else _Assumed(codes)
    if space is None:
        return None
    directions = header.get("space directions")
    try:
        d = np.eye(3) if directions is None else np.array(directions, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    return _direction_codes(d, space)


def _nrrd_geometry(header, path):
    spacing = origin = None
    directions = header.get("space directions")
    if directions is not None:
        d = np.array(directions, dtype=np.float64)
        if d.ndim != 2 or d.shape[0] != 3 or not np.all(np.isfinite(d)):
            raise InputError("space directions", f"{path!r}: expected a vector per axis, got {directions!r}")
        lengths = np.linalg.norm(d, axis=1)
        if np.any(lengths <= 0):
            raise InputError("space directions", f"{path!r}: an axis vector has length 0 in {directions!r}")
        spacing = tuple(float(v) for v in lengths)
        if d.shape[1] != 3 or not np.allclose(d, np.diag(np.diagonal(d)), rtol=0, atol=1e-9 * lengths.max()) \
                or np.any(np.diagonal(d) < 0):
            warnings.warn(f"{path}: space directions {d.tolist()} are not a positive diagonal; the volume is "
                          "used axis-aligned in index order with spacing = the vector lengths "
                          f"{spacing}", stacklevel=4)
    elif "spacings" in header:
        s = np.array(header["spacings"], dtype=np.float64)
        if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise InputError("spacings", f"{path!r}: must be three positive numbers, got {header['spacings']!r}")
        spacing = tuple(float(v) for v in s)
    if "space origin" in header:
        o = np.array(header["space origin"], dtype=np.float64)
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise InputError("space origin", f"{path!r}: must be three finite numbers, got {header['space origin']!r}")
        origin = tuple(float(v) for v in o)
    return spacing, origin
