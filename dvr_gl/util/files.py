"""Writing files so that nothing is ever half-written."""

import os
import secrets


def atomic_write(path, data: bytes):
    """Write ``data`` to a temporary file beside ``path``, flush it to disk, then rename
    it over ``path``: readers see the old file or the whole new one, never a part; on
    any failure the temporary file is removed and ``path`` is left as it was."""
    directory = os.path.dirname(os.path.abspath(path))
    tmp, fd = _temporary(directory, os.path.basename(path))
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def _temporary(directory, name):
    """A new file beside the target, created with the usual permissions (0666 less the
    umask, as open() would give the target itself)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    for _ in range(100):
        tmp = os.path.join(directory, f".{name}.{secrets.token_hex(4)}.tmp")
        try:
            return tmp, os.open(tmp, flags, 0o666)
        except FileExistsError:
            continue
    raise FileExistsError(f"could not create a temporary file in {directory!r}")
