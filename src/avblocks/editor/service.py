"""The editor's operations as plain Python: one :class:`EditorService` serves
both transports (the HTTP server of ``avblocks edit`` and the Jupyter widget).

Every operation of ``src/avblocks/editor/API.md`` is one method here taking
and returning JSON-ready values; each concern lives in a module of its own,
beside the limits that apply to it:

* :mod:`~avblocks.editor.files`: ``files``, ``load``, ``save``: the scenario
  files under the service's folder (atomically, only under that folder,
  only ``.yaml``/``.yml``);
* :mod:`~avblocks.editor.validation`: ``validate``: the document built into
  a :class:`~avblocks.Diagram` with the library's own checks, every error
  mapped to the block, port, wire or cycle it names;
* :mod:`~avblocks.editor.runs`: ``run``/``status``/``cancel``/``signal``/
  ``figure``: a run in a background thread with progress, its outcome line,
  figures and logged signals;
* :mod:`~avblocks.editor.lives`: ``live``: the drawn diagram in the live view;
* ``palette`` (:mod:`~avblocks.editor.catalog`) and ``export``
  (:mod:`~avblocks.editor.export`): a Python script, SVG or PNG.

Nothing typed in the page is executed: block types come from the scenario
loader's registry, values are data (numbers, lists, ``$parameter``
references, generator mappings), exactly as in a scenario file.
"""

from __future__ import annotations

import copy
import math
import time
import weakref
from pathlib import Path
from typing import NamedTuple

from .documents import EDITOR_KEY, EMPTY_DOCUMENT, scenario_data
from .errors import EditorError, error_json
from .files import Folder
from .lives import LiveViews
from .runs import MPL_LOCK, Runs
from .validation import Checker

__all__ = ["EDITOR_KEY", "EMPTY_DOCUMENT", "EditorError", "EditorService", "error_json",
           "scenario_data", "OPERATIONS"]


class Arg(NamedTuple):
    """One argument of an operation: its JSON type and whether it must be
    given (an optional one may also be ``null``: the default)."""

    kind: str               # "text", "bool", "number" or "mapping"
    required: bool = False
    refused: str = "BadRequest"     # the error kind when it has another type


_TEXT, _BOOL, _NUMBER, _MAP = Arg("text"), Arg("bool"), Arg("number"), Arg("mapping")
_NEED_TEXT, _DOCUMENT = Arg("text", True), Arg("mapping", True, "BadDocument")

#: Every operation of ``API.md`` and the JSON type of each of its arguments;
#: :meth:`EditorService.call` refuses anything else (400 ``BadRequest``,
#: naming the argument) before the operation runs: an unknown argument, a
#: missing required one, ``"yes"`` for a boolean, ``5`` for a path.
OPERATIONS = {
    "palette": {},
    "files": {},
    "new": {},
    "load": {"path": _TEXT, "builtin": _TEXT},
    "validate": {"document": _DOCUMENT, "path": _TEXT},
    "save": {"path": _NEED_TEXT, "document": _DOCUMENT, "revision": _TEXT, "draft": _BOOL,
             "origin": _TEXT, "create": _BOOL},
    "run": {"document": _DOCUMENT, "backend": _TEXT, "t_final": _NUMBER, "dt": _NUMBER,
            "path": _TEXT, "figures": _BOOL},
    "status": {"run": _NEED_TEXT},
    "cancel": {"run": _NEED_TEXT},
    "signal": {"run": _NEED_TEXT, "name": _NEED_TEXT},
    "live": {"document": _DOCUMENT, "path": _TEXT},
    "live_stop": {"url": _TEXT},
    "export": {"document": _DOCUMENT, "format": _TEXT, "path": _TEXT},
}
#: Longest text argument (a path, a name, a run id), in characters.
MAX_TEXT_ARG = 4096
#: Largest picture an export hands back (bytes).
MAX_EXPORT_BYTES = 32 * 1024**2

_TYPES = {"text": (str,), "bool": (bool,), "number": (int, float), "mapping": (dict,)}
_NAMES = {"text": "text", "bool": "true or false", "number": "a number",
          "mapping": "a JSON object"}


def checked_args(op, args) -> dict:
    """``args`` of operation ``op`` checked against :data:`OPERATIONS` (nulls
    of optional arguments dropped); an :class:`EditorError` otherwise."""
    spec = OPERATIONS.get(op) if isinstance(op, str) else None
    if spec is None:
        raise EditorError(f"unknown operation '{str(op)[:80]}'", status=404, kind="NotFound",
                          hint=f"operations: {sorted(OPERATIONS)}")
    if args is None:
        args = {}
    if not isinstance(args, dict):
        raise EditorError(f"the arguments of '{op}' are a JSON object", kind="BadRequest")
    out = {}
    for key, value in args.items():
        arg = spec.get(key)
        if arg is None:
            raise EditorError(f"bad arguments for '{op}': unknown argument "
                              f"'{str(key)[:80]}'", kind="BadRequest",
                              hint=f"'{op}' takes {sorted(spec) or 'no arguments'}")
        if value is None and not arg.required:
            continue
        ok = isinstance(value, _TYPES[arg.kind]) and \
            (arg.kind == "bool" or not isinstance(value, bool))
        if ok and arg.kind == "number":
            ok = math.isfinite(value)
        if ok and arg.kind == "text":
            ok = len(value) <= MAX_TEXT_ARG
        if not ok:
            found = type(value).__name__ if not isinstance(value, str) else \
                f"text of {len(value):,} characters"
            raise EditorError(f"bad arguments for '{op}': '{key}' is {_NAMES[arg.kind]}"
                              + (f" of at most {MAX_TEXT_ARG} characters"
                                 if arg.kind == "text" else ""),
                              kind=arg.refused, hint=f"found {found}")
        out[key] = value
    missing = [k for k, a in spec.items() if a.required and k not in out]
    if missing:
        raise EditorError(f"bad arguments for '{op}': missing {missing}", kind="BadRequest")
    return out


def _close(runs, lives, folder):
    """Cancel the runs and remove their folders, stop the live views, let
    the folder go (when the service is closed, let go of, or Python exits)."""
    try:
        runs.close()
        lives.close()
    finally:
        folder.close()


class EditorService:
    """The editor's operations on the scenario files under ``root``.

    Parameters
    ----------
    root : path
        The only folder files are read from and written to (default: the
        working directory).
    extra_modules : sequence of str
        Importable names of the user's block modules (``--blocks``): their
        blocks get a palette family of their own.
    figure_urls : {"path", "data"}
        How figures of a run are handed out: URLs relative to the page
        (``api/run/<run>/file/<name>``, HTTP) or data URLs (the widget).
    """

    def __init__(self, root=None, extra_modules=(), figure_urls="path"):
        self.folder = Folder(root)
        self.extra_modules = tuple(extra_modules)
        self.figure_urls = figure_urls
        self._palette = None
        self._runs = Runs(self.folder.confined)
        self._lives = LiveViews()
        self._closer = weakref.finalize(self, _close, self._runs, self._lives, self.folder)
        self._checker = Checker(self._out_for, self.extra_modules)
        #: What the page opens first: ``{"path": ...}``, ``{"builtin": ...}``
        #: or None (a new, empty diagram); ``avblocks edit NAME|FILE`` sets it.
        self.initial = None

    @property
    def root(self) -> Path:
        """The folder files are read from and written to (resolved)."""
        return self.folder.root

    @root.setter
    def root(self, root):
        if len(self._runs):
            raise EditorError("the folder cannot change while runs are kept",
                              kind="BadRequest")
        self._closer()
        self.folder = Folder(root)
        self._runs = Runs(self.folder.confined)
        self._closer = weakref.finalize(self, _close, self._runs, self._lives, self.folder)

    # ------------------------------------------------------------ paths
    def _path(self, path, *, save=False) -> Path:
        """``path`` (relative to the root) resolved, refused outside the root."""
        return self.folder.path(path, save=save)

    def _rel(self, full: Path) -> str:
        return self.folder.rel(full)

    # ---------------------------------------------------------- palette
    def palette(self) -> dict:
        """Every public block by family, the generators, the library version."""
        if self._palette is None:
            from .catalog import palette
            self._palette = palette(extra_modules=self.extra_modules)
        return self._palette

    # ------------------------------------------------------------ files
    def files(self) -> dict:
        """Scenario files under the root and the built-in case studies."""
        from ..scenarios.loader import builtin_scenarios
        builtins = [{"name": n, "kind": p.suffix.lstrip("."),
                     "editable": p.suffix in (".yaml", ".yml")}
                    for n, p in builtin_scenarios().items()]
        return {"root": str(self.root), "files": self.folder.listing(),
                "builtins": builtins, "initial": self.initial}

    def new(self) -> dict:
        """A new, empty document (parameters ``agents`` and ``seed``, a 30 s run)."""
        return {"document": copy.deepcopy(EMPTY_DOCUMENT), "path": None,
                "builtin": None, "revision": None}

    def load(self, path=None, builtin=None) -> dict:
        """The document of a file under the root, or of a built-in case study."""
        return self.folder.load(path=path, builtin=builtin)

    def save(self, path, document, revision=None, draft=False, origin=None,
             create=False) -> dict:
        """Write the document as a scenario file under the root, atomically,
        keeping the comments and forms of the file it was loaded from
        (``origin``: a built-in name or a path under the root, when it is
        not ``path`` itself). An invalid document is refused unless
        ``draft``; a file changed on disk since ``revision`` is refused (409),
        and so is an existing file when ``create`` (a "save as" that would
        replace another file: 409 ``Exists``)."""
        parts = self.folder.target(path, create=create)
        scenario_data(document)
        if origin is not None and not isinstance(origin, str):
            raise EditorError("origin is a built-in name or a path", kind="BadRequest")
        errors, _signals, _built = self.check(document, path=path)
        if errors and not draft:
            raise EditorError("the diagram has errors; save it as a draft to keep "
                              "it as it is", kind="InvalidDiagram", errors=errors)
        saved = self.folder.save(parts, document, revision=revision, origin=origin,
                                 create=bool(create))
        saved["draft"] = bool(errors)       # a draft is a file `avblocks run` refuses
        return saved

    # ------------------------------------------------------- validation
    def _source(self, path=None) -> str:
        return self.folder.source(path)

    def _out_for(self, data) -> Path:
        """The folder a scenario's blocks may write to when run."""
        from ..scenarios.paths import safe_name
        return self.root / "avblocks-out" / safe_name(data.get("name") or "untitled")

    def validate(self, document, path=None) -> dict:
        """Build the document with the library's own checks; every error found.

        The scenario loader builds it first (as ``avblocks run`` does); if
        that fails, blocks are constructed one by one, then wires connected
        one by one, then every unconnected input listed, and what remains is
        the whole diagram's error (shapes, sample times, algebraic loops,
        ``params``): as many errors as the library can tell, each with what
        it names. The document itself is never changed."""
        t0 = time.perf_counter()
        errors, signals, _built = self.check(document, path)
        return {"ok": not errors, "errors": errors, "signals": signals,
                "elapsed_ms": round(1e3 * (time.perf_counter() - t0), 2)}

    def check(self, document, path=None, fresh=False):
        """``(errors, signals, built)``: :meth:`validate`'s findings and,
        for a valid document, ``(Diagram, simulate kwargs, Scenario)``
        (remembered for a few recent scenarios: ``fresh=True`` builds anew)."""
        return self._checker.check(document, self._source(path), fresh=fresh)

    def build(self, document, path=None, fresh=False):
        """``(Diagram, simulate kwargs, Scenario)`` of a valid document
        through the scenario loader; an :class:`EditorError` with the
        errors otherwise (``fresh``: a diagram no one else holds)."""
        return self._checker.build(document, self._source(path), fresh=fresh)

    # -------------------------------------------------------------- runs
    def run(self, document, backend="numpy", t_final=None, dt=None, path=None,
            figures=True) -> dict:
        """Start a run of the document in a background thread; ``{run}``
        (``figures=False``: no figures drawn, a quick re-run)."""
        if backend not in ("numpy", "jax"):
            raise EditorError("backend is 'numpy' or 'jax'", kind="BadRequest")
        if backend == "jax":
            import importlib.util
            if importlib.util.find_spec("jax") is None:
                raise EditorError("the JAX backend needs jax, which is not installed",
                                  kind="MissingExtra", hint='pip install "avblocks[jax]"')
        overrides = {}
        for key, v in (("t_final", t_final), ("dt", dt)):
            if v is not None:
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
                    raise EditorError(f"{key} must be a number > 0", kind="BadRequest")
                overrides[key] = float(v)
        if not isinstance(figures, bool):
            raise EditorError("figures is true or false", kind="BadRequest")
        if not figures:
            overrides["figures"] = False
        self.build(document, path)
        data = copy.deepcopy(scenario_data(document))
        rid = self._runs.start(data, self._source(path), backend, overrides,
                               self.extra_modules)
        return {"run": rid}

    def status(self, run) -> dict:
        """Where a run stands: status, progress, outcome, figures, signals."""
        return self._runs.get(run).state(self.figure_urls)

    def wait(self, run, timeout=None) -> dict:
        """The run's status once it has ended (or ``timeout`` passed)."""
        r = self._runs.get(run)
        r.thread.join(timeout)
        return r.state(self.figure_urls)

    def cancel(self, run) -> dict:
        """Stop a run at its next progress tick (its partial results stay)."""
        r = self._runs.get(run)
        r.cancelled = True
        return {"run": r.id, "status": r.status}

    def signal(self, run, name) -> dict:
        """A logged signal, decimated for the wire plot."""
        return self._runs.get(run).signal(name)

    def figure(self, run, name) -> bytes:
        """The PNG bytes of a run's figure ``name`` (from the run's folder)."""
        return self._runs.get(run).figure(name)

    # -------------------------------------------------------------- live
    def live(self, document, path=None) -> dict:
        """Open the drawn diagram in the live view; ``{url}``."""
        d, sim, _sc = self.build(document, path, fresh=True)     # the view runs it
        return self._lives.open(d, sim)

    def live_stop(self, url=None) -> dict:
        """Stop the live view at ``url`` (every one the editor started when
        None); ``{stopped: [url, ...]}``."""
        return {"stopped": self._lives.stop(url)}

    # ------------------------------------------------------------ export
    def export(self, document, format="python", path=None) -> dict:
        """The diagram as a Python script (``{text}``) or a picture (``{data_url}``)."""
        if format == "python":
            from .export import to_python
            self.build(document, path)          # refuses an invalid diagram
            return {"text": to_python(scenario_data(document), self.extra_modules)}
        if format in ("svg", "png"):
            import base64

            from ..viz.diagram import draw_diagram
            d, _sim, _sc = self.build(document, path)
            with self._runs.scratch() as place:      # under the folder, removed after
                with MPL_LOCK:
                    draw_diagram(d, place.path / f"diagram.{format}", engine="matplotlib")
                raw = place.read((f"diagram.{format}",), MAX_EXPORT_BYTES)
            mime = "image/svg+xml" if format == "svg" else "image/png"
            return {"data_url": f"data:{mime};base64,"
                                + base64.b64encode(raw).decode("ascii")}
        raise EditorError("export format is 'python', 'svg' or 'png'", kind="BadRequest")

    def close(self):
        """Cancel the runs, stop live views, remove the runs' folders and any
        temporary file still being written."""
        self._closer()

    # ------------------------------------------------------------ dispatch
    def call(self, op, args) -> dict:
        """Run operation ``op`` with the JSON arguments ``args`` (both
        transports go through here), checked against :data:`OPERATIONS`
        first."""
        args = checked_args(op, args)
        return getattr(self, op)(**args)
