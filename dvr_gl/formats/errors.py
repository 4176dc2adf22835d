"""Input errors: :class:`InputError` names the field that was wrong and shows the value;
:class:`MissingFileError` is also a ``FileNotFoundError``. Helpers that turn a reader's own
failures (a missing file, a damaged one, an optional library not installed) into them."""

from __future__ import annotations

import os


class InputError(ValueError):
    """Bad input: ``field`` names what was wrong, ``detail`` says how (with the value)."""

    def __init__(self, field, detail):
        self.field = field
        self.detail = detail
        super().__init__(f"{field}: {detail}")


class MissingFileError(InputError, FileNotFoundError):
    """A file that should exist does not."""


def _existing_file(path, kind):
    """``path`` as a string, if it names an existing file (``kind``: for the message)."""
    try:
        path = os.fspath(path)
    except TypeError:
        raise InputError("path", f"expected a file name, got {path!r}") from None
    if not os.path.exists(path):
        raise MissingFileError("path", f"no such file {path!r}")
    if os.path.isdir(path):
        raise InputError("path", f"{path!r} is a directory, not a {kind} file")
    return path


def _named_errors(read):
    """A file reader whose failures on a damaged file (a cut-off array, a broken zip or
    gzip stream, a header that asks for more than there is) are InputErrors naming the
    path, not the parsing library's own exceptions. Only the reading is guarded: the
    Volume and TetMesh built from what was read name their own fields."""
    import functools

    @functools.wraps(read)
    def guarded(path, *args, **kwargs):
        try:
            return read(path, *args, **kwargs)
        except InputError:
            raise
        except Exception as e:   # EOFError, zipfile.BadZipFile, zlib.error, MemoryError, ...
            raise InputError("path", f"{os.fspath(path)!r} could not be read (damaged or cut short?): "
                                     f"{type(e).__name__}: {e}") from e
    return guarded


def _optional(module, what):
    """Import an optional reader, or an InputError saying what to install."""
    import importlib
    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError("path", f"{what} needs {module}: pip install \"dvr-gl[io]\" (or pip install "
                                 f"{module})") from None
