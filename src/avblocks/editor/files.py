"""The editor's folder: the only place it reads scenario files from and
writes them to.

:class:`Folder` resolves the page's relative paths under its root (refusing
anything outside), lists the scenario files there and reads and writes
documents through :mod:`avblocks.scenarios.document` (atomic writes that
keep a file's comments and forms).
"""

from __future__ import annotations

import os
from pathlib import Path

from ..core.errors import ScenarioError
from .errors import EditorError


class Folder:
    """Scenario files under ``root`` (default: the working directory)."""

    def __init__(self, root=None):
        self.root = Path(root if root is not None else os.getcwd()).resolve()

    def path(self, path, *, save=False) -> Path:
        """``path`` (relative to the root) resolved, refused outside the root."""
        if not isinstance(path, str) or not path.strip():
            raise EditorError("a file path is a non-empty string", kind="BadPath")
        p = Path(path)
        full = (self.root / p).resolve()
        if full != self.root and self.root not in full.parents:
            raise EditorError(f"'{path}' is outside the editor's folder '{self.root}'",
                              kind="OutsideFolder",
                              hint="the editor reads and writes only under the folder "
                                   "it was started in")
        if save and full.suffix not in (".yaml", ".yml"):
            raise EditorError(f"'{path}': scenario files are saved as .yaml or .yml",
                              kind="BadPath")
        return full

    def rel(self, full: Path) -> str:
        """``full`` (under the root) as the page names it."""
        return full.relative_to(self.root).as_posix()

    def source(self, path=None) -> str:
        """The source name a document is built under: its file (for the
        folder it may read from), else a name in the root."""
        if path:
            try:
                return str(self.path(path))
            except EditorError:
                pass
        return str(self.root / "untitled.yaml")

    def listing(self) -> list:
        """The scenario files under the root (at most 1000, in at most 5000 folders)."""
        skip = {"avblocks-out", "node_modules", "__pycache__", ".git", ".venv"}
        found = []
        for seen, (dirpath, dirnames, filenames) in enumerate(os.walk(self.root)):
            if seen >= 5000:            # started in a huge tree: list what was seen
                break
            dirnames[:] = sorted(d for d in dirnames if d not in skip
                                 and not d.startswith("."))
            for f in sorted(filenames):
                if f.endswith((".yaml", ".yml")) and not f.startswith("."):
                    full = Path(dirpath) / f
                    found.append({"path": self.rel(full), "name": full.stem})
                    if len(found) >= 1000:
                        break
            if len(found) >= 1000:
                break
        return found

    def load(self, path=None, builtin=None) -> dict:
        """The document of a file under the root, or of a built-in case study."""
        if (path is None) == (builtin is None):
            raise EditorError("load takes one of 'path' or 'builtin'", kind="BadRequest")
        if builtin is not None:
            from ..scenarios.loader import builtin_scenarios
            b = builtin_scenarios()
            if builtin not in b:
                raise EditorError(f"no built-in case study '{builtin}'", status=404,
                                  kind="NotFound", hint=f"built-in: {sorted(b)}")
            full = b[builtin]
            if full.suffix not in (".yaml", ".yml"):
                raise EditorError(f"'{builtin}' is a Python case study: it has no "
                                  "scenario file to draw", kind="NotEditable")
            rel = None
        else:
            full = self.path(path)
            if not full.is_file():
                raise EditorError(f"no such file '{path}'", status=404, kind="NotFound")
            rel = self.rel(full)
        from ..scenarios import document as doc
        try:
            return doc.load_document(builtin if builtin is not None else rel, root=self.root)
        except ScenarioError as e:
            raise EditorError(str(e), kind="ScenarioError") from None

    def target(self, path, *, create=False) -> Path:
        """Where a save of ``path`` would write: a ``.yaml``/``.yml`` file
        under the root that is not a folder, and that does not exist yet
        when ``create`` (a "save as" that would replace another file: 409
        ``Exists``)."""
        full = self.path(path, save=True)
        if create and full.exists():
            raise EditorError(f"'{path}' exists already; save again to replace it",
                              status=409, kind="Exists")
        if full.is_dir():
            raise EditorError(f"'{path}' is a folder", kind="BadPath")
        return full

    def save(self, full: Path, document, revision=None, origin=None) -> dict:
        """Write ``document`` (already checked by the caller) to ``full``
        (from :meth:`target`), atomically, keeping the comments and forms of
        the file it was loaded from (``origin``: a built-in name or a path
        under the root, when it is not the file itself). A file changed on
        disk since ``revision`` is refused (409 ``Conflict``)."""
        from ..scenarios import document as doc
        try:
            return doc.save_document(self.rel(full), document, self.root,
                                     revision=revision, draft=True, origin=origin)
        except doc.DocumentChanged as e:
            raise EditorError(str(e), status=409, kind="Conflict") from None
        except ScenarioError as e:
            raise EditorError(str(e), kind="ScenarioError") from None
