"""Writing files so that nothing is ever half-written."""

import contextlib
import os
import secrets


def atomic_write(path, data: bytes):
    """Write ``data`` to a temporary file beside ``path``, flush it to disk, then rename
    it over ``path``: readers see the old file or the whole new one, never a part; on
    any failure the temporary file is removed and ``path`` is left as it was."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)


def _temporary(directory, name, suffix=""):
    """A new file beside the target, created with the usual permissions (0666 less the
    umask, as open() would give the target itself)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    for _ in range(100):
        tmp = os.path.join(directory, f".{name}.{secrets.token_hex(4)}.tmp{suffix}")
        try:
            return tmp, os.open(tmp, flags, 0o666)
        except FileExistsError:
            continue
    raise FileExistsError(f"could not create a temporary file in {directory!r}")


@contextlib.contextmanager
def atomic_path(path, suffix=""):
    """For writers that take a file name (meshio, ffmpeg): yields a new temporary name
    beside ``path`` (ending in ``suffix``, for writers that go by extension); when the
    block ends the file is flushed to disk and renamed over ``path``. On any failure the
    temporary file is removed and ``path`` is left as it was."""
    directory = os.path.dirname(os.path.abspath(path))
    tmp, fd = _temporary(directory, os.path.basename(path), suffix)   # the name is ours alone
    os.close(fd)
    try:
        yield tmp
        with open(tmp, "rb+") as f:              # on disk before the rename
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
