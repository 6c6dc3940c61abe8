"""Across processes: where the compiled engine keeps its programs and plans.

A compiled run is worth keeping: its XLA program (seconds to compile) and
the neighbour-search plans it grew (a re-plan costs a second compile). Both
are kept in the user's cache folder by default, so that a second process
with the same diagram -- a notebook restarted, the same command run again
-- compiles nothing:

=================  ==========================================================
``<cache>/jax/``   JAX's persistent compilation cache (XLA executables; key:
                   the program's HLO, compile options, JAX version, device)
``<cache>/plans/`` grown plans, one JSON file per diagram structure
                   (:mod:`avblocks.core.compiled.plans`), in a folder named
                   after the avblocks and JAX versions
=================  ==========================================================

``<cache>`` is :func:`cache_dir`: ``$AVBLOCKS_CACHE_DIR``, else the
platform's cache folder (``platformdirs.user_cache_dir("avblocks")``:
``$XDG_CACHE_HOME/avblocks`` or ``~/.cache/avblocks`` on Linux,
``~/Library/Caches/avblocks`` on macOS, ``%LOCALAPPDATA%\\avblocks\\Cache``
on Windows).

Which folder a runner uses (:func:`resolve`): ``compile(..., cache=None)``
(the default) the cache folder unless ``$AVBLOCKS_CACHE`` says off
(``0``, ``off``, ``no``, ``false``); ``cache=False`` none; ``cache=True``
the cache folder even so; ``cache="some/folder"`` that folder.

Safe to share between the user's processes, not with other users:

- a folder is used only when it is the user's own and no one else may
  write to it (POSIX: owner is this user, no group/other write bit; made
  with mode 0700). Else a warning says so and the run goes without it: a
  program read from the cache is machine code that runs;
- plans are data (JSON), validated on read (types, bounds: a capacity no
  larger than the search's point count, the search's own reach, box and
  dimension); a damaged or foreign entry is ignored with a warning and the
  search is planned afresh (never pickle, nothing executed);
- a damaged program entry is JAX's to judge: it warns and compiles;
- processes share the folder safely: plan files are written whole
  (atomically), and JAX reads and writes its programs under a file lock
  (``filelock``), keeping at most :data:`MAX_BYTES` of them (the least
  recently used go first).

JAX's cache is one setting of the process: the first runner that uses a
folder turns it on there (unless JAX's ``jax_compilation_cache_dir`` was set
by the user: then programs go to the user's folder, plans still to ours),
keeping every program (no minimum compile time, so a second process
compiles nothing at all). A runner with ``cache=False`` compiles with
JAX's cache turned off for its own compiles.
"""

from __future__ import annotations

import os
import stat
import threading
import warnings
from contextlib import contextmanager
from pathlib import Path

from ..errors import ParameterError
from . import _jax

_OFF = ("0", "off", "no", "false")
_LOCK = threading.Lock()
#: the folder of JAX's persistent cache that avblocks set (None: none)
_JAX = {"dir": None}
_WARNED: set = set()
_SAFE: dict = {}            # folder -> verdict (checked once a process)


def cache_dir() -> Path:
    """The user's cache folder of avblocks (see the module docstring):
    ``$AVBLOCKS_CACHE_DIR``, else the platform's user cache folder."""
    if os.environ.get("AVBLOCKS_CACHE_DIR"):
        return Path(os.environ["AVBLOCKS_CACHE_DIR"]).expanduser()
    try:
        import platformdirs
    except ImportError:                         # pragma: no cover - a minimal install
        base = os.environ.get("XDG_CACHE_HOME") or (
            os.environ.get("LOCALAPPDATA") if os.name == "nt" else None)
        return (Path(base) if base else Path.home() / ".cache") / "avblocks"
    return Path(platformdirs.user_cache_dir("avblocks", appauthor=False))


def cache_disabled() -> bool:
    """True when ``$AVBLOCKS_CACHE`` says off (``0``, ``off``, ``no``, ``false``)."""
    return os.environ.get("AVBLOCKS_CACHE", "").strip().lower() in _OFF


def resolve(cache=None) -> Path | None:
    """The folder a runner keeps its programs and plans in, or None.

    ``cache``: None (default: :func:`cache_dir` unless ``$AVBLOCKS_CACHE``
    says off), False (none), True (:func:`cache_dir`) or a folder."""
    if cache is None:
        return None if cache_disabled() else cache_dir()
    if cache is False:
        return None
    if cache is True:
        return cache_dir()
    if isinstance(cache, (str, os.PathLike)) and str(cache):
        return Path(cache).expanduser()
    raise ParameterError("cache must be None, True, False or a folder", param="cache",
                         expected="None, True, False or a path", found=repr(cache)[:60])


def _warn_once(key, msg):
    if key not in _WARNED:
        _WARNED.add(key)
        warnings.warn(msg, RuntimeWarning, stacklevel=4)


def _unsafe(path: Path) -> str | None:
    """Why ``path`` (an existing folder) must not be trusted, or None."""
    if os.name != "posix":
        return None
    st = path.stat()
    if hasattr(os, "getuid") and st.st_uid != os.getuid():
        return f"it belongs to user id {st.st_uid}, not to this user ({os.getuid()})"
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"others may write to it (mode {stat.filemode(st.st_mode)})"
    return None


def usable(root: Path | None) -> Path | None:
    """``root`` made (mode 0700) and checked (see the module docstring), or
    None with a warning (once a process per folder) when it cannot be used."""
    if root is None:
        return None
    root = Path(root)
    key = str(root)
    with _LOCK:
        if key in _SAFE:
            return _SAFE[key]
    why = None
    try:
        for d in (root, root / "jax", root / "plans"):
            d.mkdir(mode=0o700, parents=True, exist_ok=True)
            why = why or _unsafe(d)
    except OSError as e:
        why = f"it cannot be made or read ({e.strerror or e})"
    got = None if why else root
    if why:
        _warn_once(("unsafe", key), f"avblocks: the cache folder {root} is not used: {why}; "
                   "compiling afresh (set AVBLOCKS_CACHE_DIR to a folder of your own, or "
                   "AVBLOCKS_CACHE=off)")
    with _LOCK:
        _SAFE[key] = got
    return got


def use(cache=None) -> Path | None:
    """The folder a new runner uses (:func:`resolve`, checked by
    :func:`usable`), JAX's persistent cache turned on there when it is the
    first (see the module docstring). None: no folder."""
    root = usable(resolve(cache))
    if root is not None:
        _point_jax_at(root / "jax")
    return root


def _point_jax_at(folder: Path, force=False):
    """Turn JAX's persistent compilation cache on in ``folder`` unless the
    user configured JAX's own (a folder that avblocks did not set, set
    before or since: it is left alone); switch folders when a runner names
    another. ``force``: whatever was configured."""
    jax = _jax.jax()
    with _LOCK:
        now = jax.config.jax_compilation_cache_dir
        if not force and now and now != _JAX["dir"]:
            return                              # the user's own folder
        if now == str(folder):
            return
        jax.config.update("jax_compilation_cache_dir", str(folder))
        # every program is kept: a second process should compile nothing
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
        _bound_and_lock(jax)
        if now:                                 # another folder before: start over
            _reset()
        _JAX["dir"] = str(folder)


#: the most bytes of programs kept (the least recently used go first)
MAX_BYTES = 4 * 2**30


def _bound_and_lock(jax):
    """With ``filelock`` (the ``jax`` extra brings it), JAX's cache keeps at
    most :data:`MAX_BYTES` and takes a file lock around each read and
    write: two processes never see each other's half-written program.
    Without it, the folder is unbounded and a program read while another
    process writes it is one JAX warns about and compiles."""
    try:
        import filelock  # noqa: F401
    except ImportError:                         # pragma: no cover - a minimal install
        return
    try:
        jax.config.update("jax_compilation_cache_max_size", int(MAX_BYTES))
    except (AttributeError, KeyError):          # pragma: no cover - an older JAX
        pass


def _reset():
    try:
        from jax.experimental.compilation_cache import compilation_cache as cc
        cc.reset_cache()
    except (ImportError, AttributeError):       # pragma: no cover - older JAX
        pass


def forget():
    """After the folders were deleted (``avblocks cache clear``): check and
    make them again at the next use, and let JAX open its cache afresh."""
    with _LOCK:
        _SAFE.clear()
    _reset()


def set_jax_folder(folder: Path):
    """Point JAX's cache at ``folder`` whatever was configured before
    (:func:`~avblocks.core.compiled.enable_persistent_cache`)."""
    _point_jax_at(Path(folder), force=True)


@contextmanager
def programs(root):
    """Around one XLA compile of a runner whose folder is ``root``: with
    None, JAX's persistent cache is off for this compile (it may be on for
    the process); else as it is."""
    if root is not None:
        yield
        return
    jax = _jax.jax()
    on = bool(jax.config.jax_compilation_cache_dir) and \
        bool(jax.config.jax_enable_compilation_cache)
    if not on:
        yield
        return
    jax.config.update("jax_enable_compilation_cache", False)
    _reset()
    try:
        yield
    finally:
        jax.config.update("jax_enable_compilation_cache", True)
        _reset()
