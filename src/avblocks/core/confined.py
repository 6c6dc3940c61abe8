"""A folder opened once, and every file under it reached through it: reads
and writes that cannot leave the folder, whatever is renamed or linked
inside it meanwhile.

:class:`Confined` opens its root folder once and keeps the descriptor. A
relative path is walked one component at a time with ``os.open(name,
O_DIRECTORY | O_NOFOLLOW, dir_fd=parent)``, and what was opened is compared
(``os.fstat``) with what was looked at (``os.stat(..., follow_symlinks=
False)``), as CPython's ``shutil.rmtree`` does: a symbolic link is never
followed, a folder swapped for a link between the look and the open is
caught, and a file is created, renamed and removed relative to the
descriptor of the folder it was found in, never by name from the root. A
path's ``..`` is taken lexically (no link is ever followed, so ``a/..`` is
the folder ``a`` is in) and may not climb above the root.

Writes are atomic: a temporary ``.NAME.XXXXXXXX.part.yaml`` created
(``O_CREAT | O_EXCL | O_NOFOLLOW``) in the same opened folder, flushed to
disk, then ``os.replace(..., src_dir_fd=, dst_dir_fd=)`` (or ``os.link`` when
the name may not exist yet); the temporary is removed on every exit path,
and the ones still being written are removed by :meth:`Confined.close`
(which the editor calls on SIGTERM/SIGINT).

This is the one module of the editor's side that differs between operating
systems:

* **Linux, macOS, BSD** (``os.open`` takes ``dir_fd`` and ``O_NOFOLLOW``):
  as above. A library that only takes a path (Matplotlib saving a figure)
  is handed ``/proc/self/fd/N/...`` on Linux, which names the opened folder
  itself, not whatever its name points to now; elsewhere the folder's name,
  checked to be the opened folder.
* **Windows** (no ``dir_fd``; creating symbolic links needs a privilege
  there): each component is looked at with ``os.lstat`` (a link or junction
  is refused) and each opened file's real path (``os.path.realpath``) must
  lie under the root and be the file that was opened (``os.fstat`` against
  ``os.stat``). This fallback checks after the fact: a swap in the instant
  between the check and the use is refused when it is noticed and the
  temporary removed, not prevented. Tests force it on Linux
  (``Confined(root, dir_fd=False)``).

Two other things differ by platform, and live here too: :func:`trim_memory`
(glibc's ``malloc_trim``: hand freed memory back to the system; nothing
elsewhere) and :func:`stop_signals` (the signals that ask a server to stop).

Paths are limited before anything is opened: at most
:data:`MAX_PATH_CHARS` characters, :data:`MAX_PATH_PARTS` components, each
name at most :data:`MAX_NAME_BYTES` bytes, no NUL character.
"""

from __future__ import annotations

import contextlib
import errno
import itertools
import os
import secrets
import shutil
import stat
import threading
from pathlib import Path

from .errors import ScenarioError

#: Longest path accepted (characters), before anything is opened.
MAX_PATH_CHARS = 1024
#: Most components (folders and the file name) a path may have.
MAX_PATH_PARTS = 32
#: Longest file or folder name (bytes, UTF-8): the common file systems' limit.
MAX_NAME_BYTES = 255

_CLOEXEC = getattr(os, "O_CLOEXEC", 0)
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_DIRECTORY = getattr(os, "O_DIRECTORY", 0)
_NONBLOCK = getattr(os, "O_NONBLOCK", 0)
_BINARY = getattr(os, "O_BINARY", 0)


def _dir_fd_supported() -> bool:
    need = (os.open, os.stat, os.mkdir, os.rename, os.unlink, os.rmdir)
    return (all(f in os.supports_dir_fd for f in need) and os.scandir in os.supports_fd
            and bool(_NOFOLLOW) and bool(_DIRECTORY)
            and getattr(shutil.rmtree, "avoids_symlink_attacks", False))


#: Whether this system walks folders by descriptor (else: the real-path fallback).
DIR_FD = _dir_fd_supported()


class FolderError(ScenarioError):
    """A path refused, or a file under the folder that could not be read or
    written. ``kind`` says which: ``OutsideFolder`` (leaves the folder:
    ``..`` above it, an absolute path elsewhere, a symbolic link),
    ``BadPath`` (not a usable name: NUL, too long, too deep, a folder where
    a file is wanted), ``NotFound``, ``Exists`` (an exclusive create found
    the name taken), ``TooLarge`` (a file over the read limit) or
    ``IOError`` (the system refused: permission, disk full)."""

    def __init__(self, cause, *, kind="BadPath", hint=None):
        self.kind = kind
        super().__init__(cause, hint=hint)


def _outside(path, root, why="", label="the folder"):
    return FolderError(f"'{path}' is outside {label} '{root}'{why}", kind="OutsideFolder",
                       hint="only files under it are read or written, and symbolic "
                            "links are not followed")


def _reason(e: OSError) -> str:
    if e.errno in (errno.ENOSPC, getattr(errno, "EDQUOT", -1)):
        return "the disk is full"
    if isinstance(e, PermissionError):
        return "permission denied"
    if e.errno == errno.EROFS:
        return "the file system is read-only"
    return e.strerror or type(e).__name__


def split(path, root, label="the folder") -> tuple:
    """The components of ``path`` relative to ``root`` (a resolved folder),
    checked as names only: a :class:`FolderError` for anything that is not
    a path (not text, NUL, too long or deep, a name over
    :data:`MAX_NAME_BYTES` bytes) or that leaves the root (``..`` above it,
    an absolute path elsewhere, another drive)."""
    if isinstance(path, os.PathLike):
        path = os.fspath(path)
    if not isinstance(path, str) or not path.strip():
        raise FolderError("a path is a non-empty string", kind="BadPath")
    shown = path if len(path) <= 80 else path[:77] + "..."
    if "\x00" in path:
        raise FolderError(f"'{shown!r}' holds a NUL character", kind="BadPath")
    if len(path) > MAX_PATH_CHARS:
        raise FolderError(f"a path of {len(path):,} characters, more than {MAX_PATH_CHARS:,}",
                          kind="BadPath")
    root = Path(root)
    p = Path(path)
    if p.is_absolute():
        try:
            p = p.relative_to(root)
        except ValueError:
            raise _outside(shown, root, label=label) from None
    elif p.drive or p.root:            # Windows: "C:x" or "\\x"
        raise _outside(shown, root, label=label)
    parts: list[str] = []
    for part in p.parts:
        if part in ("", "."):
            continue
        if part == "..":
            if not parts:
                raise _outside(shown, root, label=label)
            parts.pop()
            continue
        try:
            size = len(os.fsencode(part))
        except UnicodeError:
            raise FolderError(f"'{shown!r}' is not a valid file name on this system",
                              kind="BadPath") from None
        if size > MAX_NAME_BYTES:
            raise FolderError(f"a name of {size} bytes, longer than {MAX_NAME_BYTES} "
                              f"('{part[:40]}...')", kind="BadPath")
        parts.append(part)
        if len(parts) > MAX_PATH_PARTS:
            raise FolderError(f"a path deeper than {MAX_PATH_PARTS} folders",
                              kind="BadPath")
    return tuple(parts)


# ------------------------------------------------------------------ the two ways
class _ByFd:
    """Folders as descriptors; every call relative to one (``dir_fd``)."""

    def __init__(self, root: Path):
        self.root = root
        self.top = os.open(root, os.O_RDONLY | _DIRECTORY | _CLOEXEC)
        self.proc = os.path.isdir(f"/proc/self/fd/{self.top}")

    def dup(self, h=None):
        return os.dup(self.top if h is None else h)

    def close(self, h):
        os.close(h)

    def stat(self, h, name):
        return os.stat(name, dir_fd=h, follow_symlinks=False)

    def fstat(self, h):
        return os.fstat(h)

    def mkdir(self, h, name):
        os.mkdir(name, 0o777, dir_fd=h)

    def open_dir(self, h, name):
        return os.open(name, os.O_RDONLY | _DIRECTORY | _NOFOLLOW | _CLOEXEC, dir_fd=h)

    def open_file(self, h, name, flags, mode=0o666):
        return os.open(name, flags | _NOFOLLOW | _CLOEXEC | _BINARY, mode, dir_fd=h)

    def check_file(self, h, name, fd):
        pass                            # O_NOFOLLOW and the dir_fd did it

    def replace(self, h, src, dst):
        os.replace(src, dst, src_dir_fd=h, dst_dir_fd=h)

    def link(self, h, src, dst):
        os.link(src, dst, src_dir_fd=h, dst_dir_fd=h, follow_symlinks=False)

    def unlink(self, h, name):
        os.unlink(name, dir_fd=h)

    def rmdir(self, h, name):
        os.rmdir(name, dir_fd=h)

    def rmtree(self, h, name):
        shutil.rmtree(name, dir_fd=h)

    def scandir(self, h):
        return os.scandir(h)

    def path_of(self, h, fallback: Path) -> str:
        if self.proc:
            return f"/proc/self/fd/{h}"
        st = os.stat(fallback, follow_symlinks=False)
        if not os.path.samestat(st, os.fstat(h)):
            raise _outside(fallback, self.root, ": it was renamed or replaced")
        return str(fallback)


class _ByName:
    """The fallback: folders as full paths, each use checked afterwards on
    the real path of what was opened."""

    def __init__(self, root: Path):
        self.root = root
        self.top = root
        self._top_st = os.stat(root)

    def dup(self, h=None):
        if h is not None:
            return h
        if not os.path.samestat(os.stat(self.root), self._top_st):
            raise FolderError(f"the folder '{self.root}' was replaced", kind="OutsideFolder")
        return self.root

    def close(self, h):
        pass

    def stat(self, h, name):
        return os.lstat(os.path.join(h, name))

    def fstat(self, h):
        return os.stat(h, follow_symlinks=False)

    def mkdir(self, h, name):
        os.mkdir(os.path.join(h, name), 0o777)

    def open_dir(self, h, name):
        p = Path(h) / name
        st = os.lstat(p)
        if stat.S_ISLNK(st.st_mode) or _reparse(st):
            raise OSError(errno.ELOOP, "a symbolic link", str(p))
        self._inside(p)
        return p

    def open_file(self, h, name, flags, mode=0o666):
        return os.open(os.path.join(h, name), flags | _NOFOLLOW | _CLOEXEC | _BINARY, mode)

    def check_file(self, h, name, fd):
        p = os.path.join(h, name)
        real = self._inside(p)
        if not os.path.samestat(os.fstat(fd), os.stat(real)):
            raise _outside(p, self.root, ": the file opened is not the one named")

    def _inside(self, p):
        real = os.path.realpath(p)
        try:
            if os.path.commonpath([real, str(self.root)]) == str(self.root):
                return real
        except ValueError:              # another drive
            pass
        raise _outside(p, self.root)

    def replace(self, h, src, dst):
        self._inside(os.path.join(h, src))
        os.replace(os.path.join(h, src), os.path.join(h, dst))
        self._inside(os.path.join(h, dst))

    def link(self, h, src, dst):
        os.link(os.path.join(h, src), os.path.join(h, dst), follow_symlinks=False)

    def unlink(self, h, name):
        os.unlink(os.path.join(h, name))

    def rmdir(self, h, name):
        os.rmdir(os.path.join(h, name))

    def rmtree(self, h, name):
        p = Path(h) / name
        self._inside(p)
        shutil.rmtree(p)

    def scandir(self, h):
        return os.scandir(h)

    def path_of(self, h, fallback: Path) -> str:
        return self._inside(h)


def _reparse(st) -> bool:
    """A Windows reparse point (junction, mount point): treated as a link."""
    attrs = getattr(st, "st_file_attributes", 0)
    return bool(attrs & getattr(stat, "FILE_ATTRIBUTE_REPARSE_POINT", 0))


# ------------------------------------------------------------------ the folder
class Confined:
    """A folder opened once; files under it read, listed and written
    through it (see the module docstring).

    Parameters
    ----------
    root : path
        The folder (resolved once, when it is opened).
    dir_fd : bool, optional
        Walk by descriptor (default: where the system can, :data:`DIR_FD`);
        False forces the real-path fallback (what Windows uses).
    label : str
        What messages call the folder ("the editor's folder").
    """

    def __init__(self, root, *, dir_fd=None, label="the folder"):
        self.root = Path(root).resolve()
        self.label = label
        use_fd = DIR_FD if dir_fd is None else (bool(dir_fd) and DIR_FD)
        self.by_fd = use_fd
        self._os = _ByFd(self.root) if use_fd else _ByName(self.root)
        self._lock = threading.Lock()
        self._pending: dict[int, tuple] = {}      # temporaries being written
        self._keys = itertools.count()
        self._closed = False

    # --------------------------------------------------------------- names
    def split(self, path) -> tuple:
        """:func:`split` against this root."""
        return split(path, self.root, self.label)

    def rel(self, parts) -> str:
        """The components as the page names them (``a/b.yaml``)."""
        return "/".join(parts)

    def full(self, parts) -> Path:
        """The components as a path under the root (for messages and for
        readers that only take a path: check with :meth:`stat` first)."""
        return self.root.joinpath(*parts)

    # --------------------------------------------------------------- folders
    def _walk(self, parts, create=False, start=None):
        """A handle on the folder ``parts`` (under the folder handle ``start``,
        default the root); the caller closes it."""
        o = self._os
        h = o.dup(start)
        try:
            for i, name in enumerate(parts):
                shown = "/".join(parts[:i + 1])
                try:
                    st = o.stat(h, name)
                except FileNotFoundError:
                    if not create:
                        raise FolderError(f"no folder '{shown}'", kind="NotFound") from None
                    with contextlib.suppress(FileExistsError):
                        o.mkdir(h, name)
                    st = o.stat(h, name)
                if stat.S_ISLNK(st.st_mode) or _reparse(st):
                    raise _outside(shown, self.root, f": '{shown}' is a symbolic link",
                                   self.label)
                if not stat.S_ISDIR(st.st_mode):
                    raise FolderError(f"'{shown}' is a file, not a folder", kind="BadPath")
                try:
                    child = o.open_dir(h, name)
                except OSError as e:
                    if e.errno in (errno.ELOOP, errno.ENOTDIR, errno.ENOENT):
                        raise _outside(shown, self.root, ": it was replaced while it "
                                       "was opened", self.label) from None
                    raise
                if not os.path.samestat(st, o.fstat(child)):
                    o.close(child)
                    raise _outside(shown, self.root, ": it was replaced while it was "
                                   "opened", self.label)
                o.close(h)
                h = child
            return h
        except BaseException:
            o.close(h)
            raise

    @contextlib.contextmanager
    def folder(self, parts, create=False, start=None):
        """``with c.folder(parts) as h``: a handle on that folder (under the
        folder handle ``start``, default the root), closed after."""
        try:
            h = self._walk(tuple(parts), create=create, start=start)
        except OSError as e:
            raise self._error(e, parts) from None
        try:
            yield h
        finally:
            self._os.close(h)

    def _error(self, e: OSError, parts) -> FolderError:
        shown = self.rel(parts)
        if isinstance(e, FileNotFoundError):
            return FolderError(f"no such file '{shown}'", kind="NotFound")
        if e.errno == errno.ENAMETOOLONG:
            return FolderError(f"the name '{shown[:80]}' is too long for this system",
                               kind="BadPath")
        if e.errno in (errno.ELOOP,):
            return _outside(shown, self.root, ": it is a symbolic link", self.label)
        if e.errno in (errno.EINVAL, errno.EILSEQ):
            return FolderError(f"'{shown[:80]}' is not a valid file name on this system",
                               kind="BadPath")
        if isinstance(e, (IsADirectoryError, NotADirectoryError)):
            return FolderError(f"'{shown}': a folder and a file are mixed up in this path",
                               kind="BadPath")
        return FolderError(f"'{shown}': {_reason(e)}", kind="IOError")

    def stat(self, parts):
        """``os.stat_result`` of ``parts`` (links not followed), or None when
        it (or a folder on the way) does not exist."""
        parts = tuple(parts)
        try:
            with self.folder(parts[:-1]) as h:
                return self._os.stat(h, parts[-1])
        except FolderError as e:
            if e.kind == "NotFound":
                return None
            raise
        except FileNotFoundError:
            return None
        except OSError as e:
            raise self._error(e, parts) from None

    def path_of(self, h, parts) -> str:
        """A path naming the opened folder ``h`` (of ``parts``) for a library
        that takes only paths: ``/proc/self/fd/N`` on Linux, else the
        folder's name, checked to still be that folder."""
        return self._os.path_of(h, self.full(parts))

    def open_folder(self, parts, create=False):
        """A handle on a folder kept open by the caller (:meth:`close_folder`)."""
        try:
            return self._walk(tuple(parts), create=create)
        except OSError as e:
            raise self._error(e, parts) from None

    def close_folder(self, h):
        with contextlib.suppress(OSError):
            self._os.close(h)

    # --------------------------------------------------------------- reads
    def read_bytes(self, parts, limit, *, at=None) -> bytes:
        """The bytes of the regular file ``parts``, at most ``limit``
        (``TooLarge`` beyond); ``at``: a folder handle ``parts`` is relative
        to (default: the root)."""
        parts = tuple(parts)
        if not parts:
            raise FolderError("a file name is needed", kind="BadPath")
        o = self._os
        try:
            with self.folder(parts[:-1], start=at) as h:
                try:
                    fd = o.open_file(h, parts[-1], os.O_RDONLY | _NONBLOCK)
                except OSError as e:
                    if e.errno in (errno.ELOOP, errno.EMLINK):
                        raise _outside(self.rel(parts), self.root,
                                       ": it is a symbolic link", self.label) from None
                    raise
                try:
                    o.check_file(h, parts[-1], fd)
                    st = os.fstat(fd)
                    if stat.S_ISDIR(st.st_mode):
                        raise FolderError(f"'{self.rel(parts)}' is a folder, not a file",
                                          kind="BadPath")
                    if not stat.S_ISREG(st.st_mode):
                        raise FolderError(f"'{self.rel(parts)}' is not a regular file",
                                          kind="BadPath")
                    if st.st_size > limit:
                        raise FolderError(f"'{self.rel(parts)}' is {st.st_size / 1e6:.1f} MB, "
                                          f"more than {limit / 1e6:.0f} MB", kind="TooLarge")
                    if _NONBLOCK:
                        os.set_blocking(fd, True)
                    chunks, n = [], 0
                    while n <= limit:
                        b = os.read(fd, min(1 << 20, limit + 1 - n))
                        if not b:
                            break
                        chunks.append(b)
                        n += len(b)
                finally:
                    os.close(fd)
        except OSError as e:
            raise self._error(e, parts) from None
        raw = b"".join(chunks)
        if len(raw) > limit:
            raise FolderError(f"'{self.rel(parts)}' is over {limit / 1e6:.0f} MB",
                              kind="TooLarge")
        return raw

    def listing(self, suffixes, *, skip=(), max_files=1000, max_folders=5000) -> list:
        """Regular files under the root whose names end in ``suffixes``, as
        component tuples in sorted depth-first order; hidden names, ``skip``
        names and symbolic links left out; at most ``max_files`` files from
        the first ``max_folders`` folders."""
        o = self._os
        found, seen = [], 0
        stack = [((), None)]            # (parts, handle or None: open it)
        try:
            while stack and len(found) < max_files and seen < max_folders:
                parts, h = stack.pop()
                if h is None:
                    try:
                        h = self._walk(parts)
                    except (FolderError, OSError):
                        continue        # removed or replaced meanwhile: skip it
                seen += 1
                try:
                    with o.scandir(h) as it:
                        entries = sorted((e.name, e.is_dir(follow_symlinks=False),
                                           e.is_file(follow_symlinks=False)) for e in it)
                except OSError:
                    entries = []
                finally:
                    o.close(h)
                dirs = []
                for name, is_dir, is_file in entries:
                    if name.startswith(".") or name in skip:
                        continue
                    if is_file and name.endswith(tuple(suffixes)):
                        found.append((*parts, name))
                        if len(found) >= max_files:
                            break
                    elif is_dir and len(parts) + 1 < MAX_PATH_PARTS:
                        dirs.append((*parts, name))
                stack.extend((d, None) for d in reversed(dirs))
        finally:
            for _parts, h in stack:
                if h is not None:
                    o.close(h)
        return found

    # --------------------------------------------------------------- writes
    def write_atomic(self, parts, data: bytes, *, exclusive=False):
        """Write ``data`` to ``parts`` whole or not at all (folders on the way
        created): a temporary in the same opened folder, flushed, then
        renamed over the name (``exclusive``: linked to it, so an existing
        file is never replaced: ``Exists``). Nothing is left behind on
        failure, interrupt included."""
        parts = tuple(parts)
        if not parts:
            raise FolderError("a file name is needed", kind="BadPath")
        name = parts[-1]
        stem, dot, suffix = name.rpartition(".")
        stem, suffix = (stem, dot + suffix) if dot and stem else (name, "")
        tmp = f".{stem[:60]}.{secrets.token_hex(4)}.part{suffix[:20]}"
        o = self._os
        try:
            with self.folder(parts[:-1], create=True) as h:
                st = self._stat_in(h, name)
                if st is not None and stat.S_ISDIR(st.st_mode):
                    raise FolderError(f"'{self.rel(parts)}' is a folder", kind="BadPath")
                if exclusive and st is not None:
                    raise FolderError(f"'{self.rel(parts)}' exists already", kind="Exists")
                key = self._hold(h, tmp)
                done = False
                try:
                    fd = o.open_file(h, tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL)
                    try:
                        o.check_file(h, tmp, fd)
                        view = memoryview(data)
                        while view:
                            view = view[os.write(fd, view):]
                        os.fsync(fd)
                    finally:
                        os.close(fd)
                    if exclusive:
                        self._create(h, tmp, name, parts)
                    else:
                        o.replace(h, tmp, name)
                    done = True
                finally:
                    self._release(key, remove=not done)
        except OSError as e:
            raise self._error(e, parts) from None

    def _stat_in(self, h, name):
        try:
            return self._os.stat(h, name)
        except FileNotFoundError:
            return None

    def _create(self, h, tmp, name, parts):
        o = self._os
        try:
            o.link(h, tmp, name)
        except FileExistsError:
            raise FolderError(f"'{self.rel(parts)}' exists already", kind="Exists") from None
        except OSError as e:            # no hard links here (FAT, some shares)
            if e.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EMLINK,
                               errno.EXDEV, errno.ENOSYS):
                raise
            if self._stat_in(h, name) is not None:
                raise FolderError(f"'{self.rel(parts)}' exists already",
                                  kind="Exists") from None
            o.replace(h, tmp, name)
            return
        o.unlink(h, tmp)

    def _hold(self, h, tmp):
        """Remember a temporary being written (its folder's handle duplicated,
        so that :meth:`close` can remove it whatever the writer does)."""
        dup = self._os.dup(h)
        key = next(self._keys)
        with self._lock:
            self._pending[key] = (dup, tmp)
        return key

    def _release(self, key, remove):
        with self._lock:
            held = self._pending.pop(key, None)
        if held is None:                # close() removed it already
            return
        dup, tmp = held
        try:
            if remove:
                with contextlib.suppress(OSError):
                    self._os.unlink(dup, tmp)
        finally:
            self._os.close(dup)

    def remove_tree(self, parts):
        """Remove the folder ``parts`` and everything in it (links inside are
        removed, never followed); nothing when it does not exist."""
        parts = tuple(parts)
        if not parts:
            raise FolderError("the root itself is not removed", kind="BadPath")
        try:
            with self.folder(parts[:-1]) as h:
                st = self._stat_in(h, parts[-1])
                if st is None:
                    return
                if not stat.S_ISDIR(st.st_mode):
                    self._os.unlink(h, parts[-1])
                    return
                self._os.rmtree(h, parts[-1])
        except FolderError as e:
            if e.kind != "NotFound":
                raise
        except FileNotFoundError:
            pass
        except OSError as e:
            raise self._error(e, parts) from None

    def remove_empty(self, parts) -> bool:
        """Remove the folder ``parts`` if it is empty; whether it was."""
        parts = tuple(parts)
        try:
            with self.folder(parts[:-1]) as h:
                self._os.rmdir(h, parts[-1])
            return True
        except (FolderError, OSError):
            return False

    # --------------------------------------------------------------- end
    def pending(self) -> list:
        """Names of the temporaries being written now."""
        with self._lock:
            return [tmp for _h, tmp in self._pending.values()]

    def close(self):
        """Remove the temporaries still being written and let the root go."""
        with self._lock:
            held, self._pending = list(self._pending.values()), {}
        for dup, tmp in held:
            with contextlib.suppress(OSError):
                self._os.unlink(dup, tmp)
            with contextlib.suppress(OSError):
                self._os.close(dup)
        if not self._closed and isinstance(self._os.top, int):
            with contextlib.suppress(OSError):
                os.close(self._os.top)
        self._closed = True

    def __del__(self):
        with contextlib.suppress(Exception):
            if not self._closed and isinstance(self._os.top, int):
                os.close(self._os.top)


# ------------------------------------------------------------ other differences
def trim_memory() -> bool:
    """Hand memory freed by Python and NumPy back to the system where the C
    library keeps it (glibc's ``malloc_trim``); whether it could."""
    import ctypes
    import ctypes.util
    import sys
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):      # musl, or no libc found
        return False
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    trim(0)
    return True


def stop_signals() -> list:
    """The signals that ask a server to stop on this system: SIGINT
    (Ctrl-C), SIGTERM, and SIGHUP (terminal closed) where it exists;
    Windows' SIGBREAK (Ctrl-Break)."""
    import signal
    names = ("SIGINT", "SIGTERM", "SIGHUP", "SIGBREAK")
    return [getattr(signal, n) for n in names if hasattr(signal, n)]


__all__ = ["Confined", "FolderError", "split", "DIR_FD", "MAX_PATH_CHARS",
           "MAX_PATH_PARTS", "MAX_NAME_BYTES", "trim_memory", "stop_signals"]
