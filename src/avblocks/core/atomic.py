"""Files written whole or not at all: a temporary name next to the target,
renamed into place only when the writer finished (a full disk, a crash or an
interrupt never leaves a half-written file under the real name), and an
:class:`AvError` that says why a write failed in words."""

from __future__ import annotations

import contextlib
import errno
import os
import tempfile
from pathlib import Path

from .errors import AvError


def os_reason(e) -> str:
    """Why an ``OSError`` happened, in words (disk full, read-only, ...)."""
    if getattr(e, "errno", None) in (errno.ENOSPC, errno.EDQUOT):
        return "the disk is full"
    if getattr(e, "errno", None) == errno.EFBIG:
        return "the file is larger than this process may write (file size limit)"
    if isinstance(e, PermissionError):
        return "permission denied"
    if getattr(e, "errno", None) == errno.EROFS:
        return "the file system is read-only"
    return f"{type(e).__name__}: {e}"


def umask() -> int:
    """The process's file-creation mask (read without changing it for good)."""
    old = os.umask(0o022)
    os.umask(old)
    return old


@contextlib.contextmanager
def atomic_path(path, *, hint=None):
    """``with atomic_path(p) as tmp: write(tmp)``: ``tmp`` (same folder, same
    suffix, the usual permissions) is renamed to ``p`` when the block
    succeeds and removed when it fails; an ``OSError`` becomes an
    :class:`AvError` naming ``p``."""
    path = Path(path)
    tmp = None
    ok = False
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.",
                                   suffix=f".part{path.suffix}", dir=path.parent)
        os.fchmod(fd, 0o666 & ~umask())
        os.close(fd)
        yield Path(tmp)
        os.replace(tmp, path)
        ok = True
    except OSError as e:
        raise AvError(f"could not write '{path}': {os_reason(e)}", hint=hint) from None
    finally:
        if not ok and tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def atomic_write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` through :func:`atomic_path` (flushed to
    disk before the rename); on failure ``path`` is untouched, nothing is
    left behind, and an :class:`AvError` says why."""
    with atomic_path(path, hint="nothing was left behind; free space or choose "
                                "another folder") as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    return Path(path)
