"""The editor's folder: the only place it reads scenario files from and
writes them to.

:class:`Folder` opens its root once (:class:`~avblocks.core.confined.Confined`)
and reaches every file through that descriptor: a path of the page is
split into names (``..`` may not climb above the root, an absolute path
must lie under it; no NUL, at most
:data:`~avblocks.core.confined.MAX_PATH_CHARS` characters,
:data:`~avblocks.core.confined.MAX_PATH_PARTS` folders deep, names of at
most :data:`~avblocks.core.confined.MAX_NAME_BYTES` bytes), each folder on
the way opened without following a symbolic link, and the file read or
written relative to the folder that was opened. A save is atomic (a
temporary in the same folder, renamed into place, removed on every exit
path) and keeps a file's comments and forms
(:mod:`avblocks.scenarios.document`). Listing and loading follow no link
either.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ..core.confined import Confined, FolderError
from ..core.errors import ScenarioError
from .errors import EditorError

#: Suffixes the editor saves; it loads these and ``.toml``.
SAVE_SUFFIXES = (".yaml", ".yml")
LOAD_SUFFIXES = (".yaml", ".yml", ".toml")
#: Folders the listing skips (besides hidden ones).
SKIP = {"avblocks-out", "node_modules", "__pycache__"}
#: The listing's bounds: files listed, folders looked into.
MAX_LISTED = 1000
MAX_LISTED_FOLDERS = 5000

#: HTTP status of each kind of refusal from the folder.
_STATUS = {"NotFound": 404, "Exists": 409, "IOError": 409}


def folder_error(e: FolderError) -> EditorError:
    """The editor's answer to a refusal of :mod:`avblocks.core.confined`:
    ``OutsideFolder``/``BadPath`` 400, a file over the limit
    (``FileTooLarge``) 400, ``NotFound`` 404, ``Exists`` 409, a file the
    system would not write (``FileError``) 409."""
    kind = {"IOError": "FileError", "TooLarge": "FileTooLarge"}.get(e.kind, e.kind)
    return EditorError(str(e), status=_STATUS.get(e.kind, 400), kind=kind)


class Folder:
    """Scenario files under ``root`` (default: the working directory).

    Parameters
    ----------
    root : path, optional
        The folder (opened once, here).
    dir_fd : bool, optional
        Force the real-path fallback (False) that systems without
        ``dir_fd`` use (see :mod:`avblocks.core.confined`).
    """

    def __init__(self, root=None, *, dir_fd=None):
        self.confined = Confined(root if root is not None else os.getcwd(), dir_fd=dir_fd,
                                 label="the editor's folder")
        self.root = self.confined.root

    # ------------------------------------------------------------- names
    def parts(self, path, *, save=False) -> tuple:
        """``path`` (relative to the root, or absolute under it) as names;
        an :class:`EditorError` (400 ``OutsideFolder`` or ``BadPath``)
        for anything else, and for a suffix other than ``.yaml``/``.yml``
        when ``save``."""
        try:
            parts = self.confined.split(path)
        except FolderError as e:
            raise folder_error(e) from None
        if not parts:
            raise EditorError(f"'{path}' is the editor's folder, not a file", kind="BadPath")
        if save and Path(parts[-1]).suffix not in SAVE_SUFFIXES:
            raise EditorError(f"'{path}': scenario files are saved as .yaml or .yml",
                              kind="BadPath")
        return parts

    def path(self, path, *, save=False) -> Path:
        """``path`` as a full path under the root (checked as names: see
        :meth:`parts`; what is opened is checked again when it is opened)."""
        return self.confined.full(self.parts(path, save=save))

    def rel(self, full) -> str:
        """``full`` (a path under the root, or names) as the page names it."""
        if isinstance(full, tuple):
            return self.confined.rel(full)
        return Path(full).relative_to(self.root).as_posix()

    def source(self, path=None) -> str:
        """The source name a document is built under: its file (for the
        folder it may read from), else a name in the root."""
        if path:
            try:
                return str(self.path(path))
            except EditorError:
                pass
        return str(self.root / "untitled.yaml")

    # ------------------------------------------------------------- reads
    def listing(self) -> list:
        """The scenario files under the root (at most :data:`MAX_LISTED`, in
        the first :data:`MAX_LISTED_FOLDERS` folders; hidden names, skipped
        folders and symbolic links left out)."""
        found = self.confined.listing(SAVE_SUFFIXES, skip=SKIP, max_files=MAX_LISTED,
                                      max_folders=MAX_LISTED_FOLDERS)
        return [{"path": self.confined.rel(p), "name": Path(p[-1]).stem} for p in found]

    def load(self, path=None, builtin=None) -> dict:
        """The document of a file under the root, or of a built-in case study."""
        if (path is None) == (builtin is None):
            raise EditorError("load takes one of 'path' or 'builtin'", kind="BadRequest")
        from ..scenarios import document as doc
        if builtin is not None:
            from ..scenarios.loader import builtin_scenarios
            if not isinstance(builtin, str):
                raise EditorError("'builtin' is the name of a built-in case study",
                                  kind="BadRequest")
            b = builtin_scenarios()
            if builtin not in b:
                raise EditorError(f"no built-in case study '{builtin[:80]}'", status=404,
                                  kind="NotFound", hint=f"built-in: {sorted(b)}")
            if b[builtin].suffix not in SAVE_SUFFIXES:
                raise EditorError(f"'{builtin}' is a Python case study: it has no "
                                  "scenario file to draw", kind="NotEditable")
            target = builtin
        else:
            parts = self.parts(path)
            if Path(parts[-1]).suffix not in LOAD_SUFFIXES:
                raise EditorError(f"'{path}': scenario files are .yaml, .yml or .toml",
                                  kind="BadPath")
            target = self.confined.rel(parts)
        try:
            return doc.load_document(target, root=self.confined)
        except FolderError as e:
            raise folder_error(e) from None
        except ScenarioError as e:
            raise EditorError(str(e), kind="ScenarioError") from None

    # ------------------------------------------------------------- writes
    def target(self, path, *, create=False) -> tuple:
        """Where a save of ``path`` would write (as names): a ``.yaml``/
        ``.yml`` file under the root that is not a folder, and that does
        not exist yet when ``create`` (a "save as" that would replace
        another file: 409 ``Exists``)."""
        parts = self.parts(path, save=True)
        try:
            st = self.confined.stat(parts)
        except FolderError as e:
            raise folder_error(e) from None
        if create and st is not None:
            raise EditorError(f"'{path}' exists already; save again to replace it",
                              status=409, kind="Exists")
        if st is not None and stat.S_ISDIR(st.st_mode):
            raise EditorError(f"'{path}' is a folder", kind="BadPath")
        return parts

    def save(self, parts, document, revision=None, origin=None, create=False) -> dict:
        """Write ``document`` (already checked by the caller) to ``parts``
        (from :meth:`target`), atomically, keeping the comments and forms of
        the file it was loaded from (``origin``: a built-in name or a path
        under the root, when it is not the file itself). A file changed on
        disk since ``revision`` is refused (409 ``Conflict``); with
        ``create``, a file that appeared meanwhile is left as it is (409
        ``Exists``)."""
        from ..scenarios import document as doc
        try:
            return doc.save_document(self.confined.rel(parts), document, self.confined,
                                     revision=revision, draft=True, origin=origin,
                                     create=create)
        except doc.DocumentChanged as e:
            raise EditorError(str(e), status=409, kind="Conflict") from None
        except FolderError as e:
            raise folder_error(e) from None
        except ScenarioError as e:
            raise EditorError(str(e), kind="ScenarioError") from None

    def close(self):
        """Remove temporaries still being written; let the folder go."""
        self.confined.close()
