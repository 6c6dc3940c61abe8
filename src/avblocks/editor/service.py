"""The editor's operations as plain Python: one :class:`EditorService` serves
both transports (the HTTP server of ``avblocks edit`` and the Jupyter widget).

Every operation of ``src/avblocks/editor/API.md`` is one method here taking
and returning JSON-ready values:

* ``palette``, ``files``, ``load``, ``save``: the block catalogue, the scenario
  files under the service's folder, reading and writing them (atomically,
  only under that folder, only ``.yaml``/``.yml``);
* ``validate``: the document built into a :class:`~avblocks.Diagram` with
  the library's own checks, every error mapped to the block, port, wire or
  cycle it names;
* ``run``/``status``/``cancel``/``signal``/``figure``: a run in a background
  thread with progress, its outcome line, figures and logged signals;
* ``live``: the drawn diagram in the live view; ``export``: a Python script,
  SVG or PNG.

Nothing typed in the page is executed: block types come from the scenario
loader's registry, values are data (numbers, lists, ``$parameter``
references, generator mappings), exactly as in a scenario file.
"""

from __future__ import annotations

import copy
import os
import secrets
import shutil
import tempfile
import threading
import time
from pathlib import Path

from ..core.errors import AlgebraicLoopError, AvError, ScenarioError

#: The document's own key (layout, groups, viewport): not part of the scenario.
EDITOR_KEY = "editor"
#: What a new, empty document holds.
EMPTY_DOCUMENT = {
    "name": "untitled",
    "parameters": {"agents": 15, "seed": 1},
    "blocks": {},
    "wires": [],
    "simulation": {"t_final": 30, "dt": 0.02},
}
#: At most this many time points in a signal sent for the wire plot.
MAX_SIGNAL_POINTS = 2000
#: ... and at most this many numbers in all (agents x components x points).
MAX_SIGNAL_VALUES = 400_000
#: Runs kept (with their figures) before the oldest finished one is dropped.
MAX_RUNS = 8
#: Validations remembered by their scenario (a layout-only edit, such as a
#: block moved, is answered without building again).
CHECK_CACHE = 8


class EditorError(AvError):
    """A request the editor refuses; ``status`` is the HTTP status it maps to
    (400 bad request, 404 unknown file or run, 409 file changed on disk,
    413 too large)."""

    def __init__(self, cause, *, status=400, kind=None, errors=None, hint=None):
        self.status = int(status)
        self.kind = kind or "EditorError"
        self.errors = errors
        super().__init__(cause, hint=hint)

    def to_json(self) -> dict:
        out = {"message": str(self), "kind": self.kind}
        if self.errors is not None:
            out["errors"] = self.errors
        return out


def error_json(e: BaseException) -> tuple[int, dict]:
    """``(HTTP status, {"error": {...}})`` for an exception an operation raised."""
    if isinstance(e, EditorError):
        return e.status, {"error": e.to_json()}
    if isinstance(e, AvError):
        return 400, {"error": {"message": str(e), "kind": type(e).__name__}}
    return 500, {"error": {"message": f"{type(e).__name__}: {e}", "kind": "InternalError"}}


# --------------------------------------------------------------- documents
def scenario_data(document) -> dict:
    """The scenario mapping of a document: everything but the editor's key."""
    if not isinstance(document, dict):
        raise EditorError("a document is a mapping (the scenario file's sections)",
                          kind="BadDocument")
    return {k: v for k, v in document.items() if k != EDITOR_KEY}


# -------------------------------------------------------------- validation
def _where(entry):
    """``(block, param, wire index)`` named by a loader entry such as
    ``blocks.drive.gain`` or ``wires[3]``."""
    import re
    if not entry:
        return None, None, None
    m = re.match(r"^blocks\.([A-Za-z_][A-Za-z0-9_]*)(?:\.([A-Za-z_][A-Za-z0-9_]*))?", entry)
    if m:
        param = m.group(2)
        return m.group(1), (None if param == "type" else param), None
    m = re.match(r"^wires\[(\d+)\]", entry)
    if m:
        return None, None, int(m.group(1))
    m = re.match(r"^params\.(.+)$", entry)
    if m:
        b, _, p = m.group(1).partition(".")
        return b or None, p or None, None
    return None, None, None


def error_record(e: AvError, *, block=None, port=None, param=None, wire=None,
                 cycle=None) -> dict:
    """The error record of API.md for a library error: its own message and
    kind, and what it names (the error's structured context first, then the
    place the editor knows it came from)."""
    inner = e.__context__ if isinstance(e, ScenarioError) else None
    src = inner if isinstance(inner, AvError) else e
    eb, ep, ew = _where(getattr(e, "entry", None))
    message = str(e)
    where = "".join(f"{x}: " for x in (getattr(e, "file", None), getattr(e, "entry", None))
                    if x is not None)
    if src is not e and e.cause == where + str(src):
        message = str(src)             # the loader only added where it was
    elif isinstance(e, ScenarioError) and e.file and message.startswith(f"{e.file}: "):
        message = message[len(e.file) + 2:]    # the page knows which file it is
    rec = {
        "message": message,
        "kind": type(src).__name__,
        "block": block or eb or _leaf(getattr(src, "block", None)),
        "port": port or getattr(src, "port", None),
        "param": param or getattr(src, "param", None) or ep,
        "wire": wire,
        "cycle": cycle,
    }
    if ew is not None and rec["wire"] is None:
        rec["wire"] = ew
    return rec


def _leaf(block):
    return None if block is None else str(block)


class _Collector:
    """Builds a document into a diagram piece by piece, collecting every
    error the library raises on the way (see :meth:`EditorService.validate`)."""

    def __init__(self, data, source, out, modules=()):
        from ..scenarios.loader import Scenario
        self.data = data
        self.sc = Scenario(data, source, modules=tuple(modules))
        self.out = out
        self.errors = []

    def add(self, e, **where):
        rec = error_record(e, **where)
        key = (rec["message"], rec["block"], rec["port"], str(rec["wire"]))
        if key not in {(r["message"], r["block"], r["port"], str(r["wire"]))
                       for r in self.errors}:
            self.errors.append(rec)

    def blocks(self):
        """Each block constructed on its own (the loader's rules: registry
        types only, known parameters, values resolved, files confined)."""
        import inspect

        from ..core.diagram import Diagram
        from ..core.errors import did_you_mean
        from ..scenarios.loader import block_registry
        sc = self.sc
        sc.params = dict(self.data.get("parameters") or {})
        sc._generated_bytes = 0
        reg = block_registry(code_blocks=True, modules=sc.modules, interfaces=True)
        d = Diagram(sc.name if str(sc.name).isidentifier() else None)
        for name, spec in (self.data.get("blocks") or {}).items():
            where = f"blocks.{name}"
            try:
                if not isinstance(spec, dict) or "type" not in spec:
                    raise ScenarioError("each block needs a 'type'", file=sc.source,
                                        entry=where, hint="e.g. type: vehicles.Unicycle")
                typ = spec["type"]
                if not isinstance(typ, str) or typ not in reg:
                    raise ScenarioError(f"unknown block type '{typ}'", file=sc.source,
                                        entry=f"{where}.type",
                                        hint=did_you_mean(typ, reg)
                                        + "run `avblocks list --blocks` for the types")
                cls = reg[typ]
                sig = inspect.signature(cls.__init__)
                accepted = [p for p in sig.parameters if p != "self"]
                has_var = any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values())
                bad = [k for k in spec if k != "type" and k not in accepted
                       and not has_var]
                for k in bad:
                    self.add(ScenarioError(f"unknown parameter '{k}' for {typ}",
                                           file=sc.source, entry=f"{where}.{k}",
                                           hint=did_you_mean(k, accepted)
                                           + f"{typ} takes {accepted}"),
                             block=name, param=k)
                if bad:
                    continue
                kwargs = {}
                failed = False
                for k, v in spec.items():
                    if k == "type":
                        continue
                    try:
                        kwargs[k] = sc._value(v, f"{where}.{k}")   # as the loader does
                    except AvError as e:
                        self.add(e, block=name, param=k)
                        failed = True
                if failed:
                    continue
                kwargs = sc._confine(kwargs, where, self.out)
                try:
                    block = cls(**kwargs)
                except AvError as e:
                    self.add(e, block=name, param=getattr(e, "param", None))
                    continue
                except Exception as e:  # noqa: BLE001 - a constructor's own failure
                    self.add(ScenarioError(f"{typ}: {type(e).__name__}: {e}",
                                           file=sc.source, entry=where,
                                           hint=f"{typ} takes {accepted}"), block=name)
                    continue
                d.add(block, name=name)
            except AvError as e:
                self.add(e, block=name)
        return d

    def wires(self, d):
        """Each wire connected on its own (one driver per input, port names,
        shapes, dtypes and agent counts as far as they are known)."""
        for j, w in enumerate(self.data.get("wires") or []):
            if not (isinstance(w, list) and len(w) == 2
                    and all(isinstance(s, str) for s in w)):
                self.add(ScenarioError(f'a wire is ["block.output", "block.input"], '
                                       f"found {w!r:.80}", file=self.sc.source,
                                       entry=f"wires[{j}]"), wire=j)
                continue
            refs = []
            drawn = self.data.get("blocks") or {}
            unknown = [s.partition(".")[0] for s in w if s.partition(".")[0] not in drawn]
            if unknown:
                from ..core.errors import WiringError, did_you_mean
                self.add(WiringError(f"wire names unknown block '{unknown[0]}'",
                                     hint=did_you_mean(unknown[0], drawn)
                                     + f"blocks: {sorted(drawn)}"), wire=j)
                continue
            for s in w:
                b, _, p = s.partition(".")
                if b not in d.blocks:
                    break                       # that block has its own error
                try:
                    refs.append(d[b].port(p))
                except AvError as e:
                    self.add(e, block=b, port=p, wire=j)
                    break
            if len(refs) != 2:
                continue
            try:
                d.connect(*refs)
            except AvError as e:
                self.add(e, block=refs[1].handle.name, port=refs[1].name, wire=j)


def _wire_index(data, block, port):
    """The index of the wire that drives ``block.port`` (None if none)."""
    dst = f"{block}.{port}"
    for j, w in enumerate(data.get("wires") or []):
        if isinstance(w, list) and len(w) == 2 and w[1] == dst:
            return j
    return None


def _signals(blocks) -> dict:
    """``{"block.port": {shape, dtype}}`` for every output port whose shape is known."""
    out = {}
    for name, b in blocks:
        for o, p in b.output_ports.items():
            if p.shape is not None:
                out[f"{name}.{o}"] = {"shape": str(tuple(p.shape)).replace(",)", ")"),
                                      "dtype": str(p.dtype)}
    return out


# ------------------------------------------------------------------ service
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
        self.root = Path(root if root is not None else os.getcwd()).resolve()
        self.extra_modules = tuple(extra_modules)
        self.figure_urls = figure_urls
        self._runs: dict[str, _Run] = {}
        self._lock = threading.Lock()
        self._palette = None
        self._lives = []
        self._checked = {}          # recent validations by scenario (not layout)
        #: What the page opens first: ``{"path": ...}``, ``{"builtin": ...}``
        #: or None (a new, empty diagram); ``avblocks edit NAME|FILE`` sets it.
        self.initial = None

    # ------------------------------------------------------------ paths
    def _path(self, path, *, save=False) -> Path:
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

    def _rel(self, full: Path) -> str:
        return full.relative_to(self.root).as_posix()

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
                    found.append({"path": self._rel(full), "name": full.stem})
                    if len(found) >= 1000:
                        break
            if len(found) >= 1000:
                break
        builtins = [{"name": n, "kind": p.suffix.lstrip("."),
                     "editable": p.suffix in (".yaml", ".yml")}
                    for n, p in builtin_scenarios().items()]
        return {"root": str(self.root), "files": found, "builtins": builtins,
                "initial": self.initial}

    def new(self) -> dict:
        """A new, empty document (parameters ``agents`` and ``seed``, a 30 s run)."""
        return {"document": copy.deepcopy(EMPTY_DOCUMENT), "path": None,
                "builtin": None, "revision": None}

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
            full = self._path(path)
            if not full.is_file():
                raise EditorError(f"no such file '{path}'", status=404, kind="NotFound")
            rel = self._rel(full)
        from ..scenarios import document as doc
        try:
            return doc.load_document(builtin if builtin is not None else rel, root=self.root)
        except ScenarioError as e:
            raise EditorError(str(e), kind="ScenarioError") from None

    def save(self, path, document, revision=None, draft=False, origin=None,
             create=False) -> dict:
        """Write the document as a scenario file under the root, atomically,
        keeping the comments and forms of the file it was loaded from
        (``origin``: a built-in name or a path under the root, when it is
        not ``path`` itself). An invalid document is refused unless
        ``draft``; a file changed on disk since ``revision`` is refused (409),
        and so is an existing file when ``create`` (a "save as" that would
        replace another file: 409 ``Exists``)."""
        full = self._path(path, save=True)
        if create and full.exists():
            raise EditorError(f"'{path}' exists already; save again to replace it",
                              status=409, kind="Exists")
        scenario_data(document)
        if origin is not None and not isinstance(origin, str):
            raise EditorError("origin is a built-in name or a path", kind="BadRequest")
        if not draft:
            errors, _signals, _built = self.check(document, path=path)
            if errors:
                raise EditorError("the diagram has errors; save it as a draft to keep "
                                  "it as it is", kind="InvalidDiagram", errors=errors)
        if full.is_dir():
            raise EditorError(f"'{path}' is a folder", kind="BadPath")
        from ..scenarios import document as doc
        try:                  # checked above: written as it is
            return doc.save_document(self._rel(full), document, self.root,
                                     revision=revision, draft=True, origin=origin)
        except doc.DocumentChanged as e:
            raise EditorError(str(e), status=409, kind="Conflict") from None
        except ScenarioError as e:
            raise EditorError(str(e), kind="ScenarioError") from None

    # ------------------------------------------------------- validation
    def _source(self, path=None) -> str:
        """The source name a document is built under: its file (for the
        folder it may read from), else a name in the root."""
        if path:
            try:
                return str(self._path(path))
            except EditorError:
                pass
        return str(self.root / "untitled.yaml")

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
        import json
        data = copy.deepcopy(scenario_data(document))
        source = self._source(path)
        try:        # the same scenario as lately (a block moved, say): its findings
            key = (source, json.dumps(data, sort_keys=True, allow_nan=False))
        except (TypeError, ValueError):
            key = None
        if fresh:
            key = None
        with self._lock:
            hit = self._checked.get(key) if key is not None else None
            if hit is not None:
                self._checked[key] = self._checked.pop(key)       # most recent last
        if hit is not None:
            errors, signals, built = hit
            return copy.deepcopy(errors), copy.deepcopy(signals), built
        from ..scenarios.paths import safe_name
        out = self.root / "avblocks-out" / safe_name(data.get("name") or "untitled")
        errors, signals, built = _validate(data, source, out, self.extra_modules)
        if key is not None:
            with self._lock:
                self._checked[key] = (copy.deepcopy(errors), copy.deepcopy(signals), built)
                while len(self._checked) > CHECK_CACHE:
                    self._checked.pop(next(iter(self._checked)))
        return errors, signals, built

    def build(self, document, path=None, fresh=False):
        """``(Diagram, simulate kwargs, Scenario)`` of a valid document
        through the scenario loader; an :class:`EditorError` with the
        errors otherwise (``fresh``: a diagram no one else holds)."""
        errors, _signals, built = self.check(document, path, fresh=fresh)
        if errors:
            raise EditorError("the diagram has errors", kind="InvalidDiagram",
                              errors=errors)
        return built

    # -------------------------------------------------------------- runs
    def run(self, document, backend="numpy", t_final=None, dt=None, path=None) -> dict:
        """Start a run of the document in a background thread; ``{run}``."""
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
        self.build(document, path)
        data = copy.deepcopy(scenario_data(document))
        with self._lock:
            running = sum(r.status == "running" for r in self._runs.values())
            if running >= 2:
                raise EditorError("two runs are going on already; cancel one first",
                                  status=409, kind="Busy")
            self._prune()
            rid = secrets.token_hex(6)
            r = _Run(rid, data, self._source(path), backend, overrides,
                     self.extra_modules)
            self._runs[rid] = r
        r.start()
        return {"run": rid}

    def _prune(self):
        done = [k for k, r in self._runs.items() if r.status != "running"]
        while len(self._runs) >= MAX_RUNS and done:
            self._runs.pop(done.pop(0)).discard()

    def _get(self, run) -> _Run:
        r = self._runs.get(str(run))
        if r is None:
            raise EditorError(f"no run '{run}'", status=404, kind="NotFound")
        return r

    def status(self, run) -> dict:
        """Where a run stands: status, progress, outcome, figures, signals."""
        return self._get(run).state(self.figure_urls)

    def wait(self, run, timeout=None) -> dict:
        """The run's status once it has ended (or ``timeout`` passed)."""
        r = self._get(run)
        r.thread.join(timeout)
        return r.state(self.figure_urls)

    def cancel(self, run) -> dict:
        """Stop a run at its next progress tick (its partial results stay)."""
        r = self._get(run)
        r.cancelled = True
        return {"run": r.id, "status": r.status}

    def signal(self, run, name) -> dict:
        """A logged signal, decimated for the wire plot."""
        return self._get(run).signal(name)

    def figure(self, run, name) -> Path:
        """The file of a run's figure ``name`` (a PNG in the run's folder)."""
        return self._get(run).figure(name)

    # -------------------------------------------------------------- live
    def live(self, document, path=None) -> dict:
        """Open the drawn diagram in the live view; ``{url}``."""
        try:
            from ..viz.live import LiveView
        except ImportError as e:
            raise EditorError(f"the live view needs its extra ({e})",
                              kind="MissingExtra", hint='pip install "avblocks[live]"'
                              ) from None
        d, sim, _sc = self.build(document, path, fresh=True)     # the view runs it
        sim = dict(sim)
        t_final = float(sim.pop("t_final", 10.0))
        keep = {k: sim[k] for k in ("dt", "solver", "seed", "log", "log_every", "params",
                                    "realtime") if k in sim}
        view = LiveView(d, t_final, verbose=False, **keep)
        view.start()
        self._lives = [v for v in self._lives if v._thread and v._thread.is_alive()]
        self._lives.append(view)
        return {"url": view.url}

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
            with tempfile.TemporaryDirectory() as tmp:
                with _MPL_LOCK:
                    f = draw_diagram(d, Path(tmp) / f"diagram.{format}", engine="matplotlib")
                raw = f.read_bytes()
            mime = "image/svg+xml" if format == "svg" else "image/png"
            return {"data_url": f"data:{mime};base64,"
                                + base64.b64encode(raw).decode("ascii")}
        raise EditorError("export format is 'python', 'svg' or 'png'", kind="BadRequest")

    def close(self):
        """Cancel the runs, stop live views, remove the runs' folders."""
        for r in list(self._runs.values()):
            r.cancelled = True
        for r in list(self._runs.values()):
            if r.thread is not None:
                r.thread.join(5)
            r.discard()
        self._runs.clear()
        for v in self._lives:
            v.stop()

    # ------------------------------------------------------------ dispatch
    def call(self, op, args) -> dict:
        """Run operation ``op`` with the JSON arguments ``args`` (both
        transports go through here)."""
        args = dict(args or {})
        fn = {
            "palette": self.palette, "files": self.files, "new": self.new,
            "load": self.load,
            "validate": self.validate, "save": self.save, "run": self.run,
            "status": self.status, "cancel": self.cancel, "signal": self.signal,
            "live": self.live, "export": self.export,
        }.get(op)
        if fn is None:
            raise EditorError(f"unknown operation '{op}'", status=404, kind="NotFound")
        import inspect
        try:
            inspect.signature(fn).bind(**args)
        except TypeError as e:
            raise EditorError(f"bad arguments for '{op}': {e}", kind="BadRequest"
                              ) from None
        return fn(**args)


def _validate(data, source, out, modules=()):
    """``(errors, signals, built)`` of a scenario mapping (see
    :meth:`EditorService.validate`); ``built`` is ``(Diagram, simulate
    kwargs, Scenario)`` when there is no error, else None. ``out``: the
    folder the blocks may write to when run (nothing is written here)."""
    from ..scenarios.loader import Scenario
    if not data.get("blocks"):
        # an empty drawing is not an error to mark on anything, but it does not run
        return ([{"message": "the diagram has no blocks yet", "kind": "ScenarioError",
                  "block": None, "port": None, "param": None, "wire": None,
                  "cycle": None}], {}, None)
    sc = Scenario(data, source, modules=tuple(modules))
    try:
        sc.validate()
    except AvError as e:
        return [error_record(e)], {}, None
    # the loader builds it as `avblocks run` would: when that passes, done
    try:
        d, sim = sc.build(output_dir=out)
    except AvError as e:
        whole = e
    else:
        return [], _signals((n, h.block) for n, h in d.blocks.items()), (d, sim, sc)
    # it failed: piece by piece, to find every error (not only the first)
    c = _Collector(data, source, out, modules)
    d = c.blocks()
    c.wires(d)
    for path in d.unconnected_inputs():
        b, _, p = path.rpartition(".")
        if not any(r["block"] == b and r["port"] == p for r in c.errors):
            c.add(_unconnected(b, p), block=b, port=p)
    errors = c.errors
    ws = data.get("wires") or []
    for rec in errors:
        j = rec["wire"]
        if isinstance(j, int):
            rec["wire"] = list(ws[j]) if j < len(ws) and isinstance(ws[j], list) else None
    signals = _signals((n, h.block) for n, h in d.blocks.items())
    if not errors:             # only the whole diagram is wrong (a loop, params...)
        errors = [_whole(whole, data)]
    return errors, signals, None


def _unconnected(block, port):
    from ..core.errors import WiringError
    return WiringError("input is not connected", block=block, port=port,
                       hint="draw a wire to it from an output")


def _whole(e, data):
    """The error record of a whole-diagram build failure."""
    inner = e.__context__ if isinstance(e, ScenarioError) else e
    if isinstance(inner, AlgebraicLoopError):
        cycle = []
        for w in inner.cycle:
            s, _, dd = w.partition(" -> ")
            cycle += [s, dd]
        first = cycle[0].rpartition(".")[0] if cycle else None
        return error_record(e, block=first, cycle=cycle)
    rec = error_record(e)
    if isinstance(inner, AvError) and inner.block and inner.port:
        rec["block"], rec["port"] = inner.block, inner.port
        j = _wire_index(data, inner.block, inner.port)
        rec["wire"] = None if j is None else list(data["wires"][j])
    return rec


_MPL_LOCK = threading.Lock()


class _Cancelled(KeyboardInterrupt):
    """Raised from a run's progress callback when the page cancels it."""

    signal_name = "cancelled"


class _Run:
    """One run of a document in a background thread."""

    def __init__(self, rid, data, source, backend, overrides, modules=()):
        self.id = rid
        self.modules = tuple(modules)
        self.data = data
        self.source = source
        self.backend = backend
        self.overrides = overrides
        self.status = "running"
        self.progress = 0.0
        self.t = 0.0
        self.t_final = None
        self.outcome = None
        self.numbers = {}
        self.figures = []
        self.error = None
        self.results = None
        self.cancelled = False
        self.thread = None
        self.folder = Path(tempfile.mkdtemp(prefix="avblocks-edit-"))

    def start(self):
        self.thread = threading.Thread(target=self._main, daemon=True,
                                       name=f"avblocks-edit-run-{self.id}")
        self.thread.start()

    def _tick(self, k, n):
        self.progress = k / n if n else 1.0
        if self.t_final is not None:
            self.t = self.progress * self.t_final
        if self.cancelled:
            raise _Cancelled()

    def _main(self):
        try:
            self._simulate()
        except AvError as e:
            self.error = str(e)
            self.status = "failed"
        except Exception as e:  # noqa: BLE001 - reported to the page
            self.error = f"{type(e).__name__}: {e}"
            self.status = "failed"

    def _simulate(self):
        from ..core.errors import SimulationError
        from ..core.frontend import simulate
        from ..scenarios.loader import Scenario
        from ..scenarios.report import default_figures, default_outcome
        sc = Scenario(self.data, self.source, modules=self.modules)
        d, sim = sc.build(output_dir=self.folder / "files")
        hooks, movie = sc.hooks(d, sim), sc.movie()
        sim.update(self.overrides)
        sim.setdefault("t_final", 10.0)
        self.t_final = float(sim["t_final"])
        if self.backend == "jax":
            # the compiled run goes in segments that report (and can be
            # stopped) between them: core.compiled.segments
            sim["backend"] = "jax"
        sim["progress"] = self._tick
        try:
            res = simulate(d, **sim)
        except SimulationError as e:
            self.results = e.results
            raise
        self.results = res
        self.t = float(res.t[-1]) if len(res.t) else 0.0
        if res.meta.get("interrupted"):
            # progress stays where the run stopped
            self.status = "cancelled"
            return
        self.progress = 1.0
        if hooks is not None and hooks.outcome is not None:
            self.outcome, numbers = hooks.outcome(res)
        else:
            self.outcome, numbers = default_outcome(res)
        from ..scenarios.report import jsonable
        self.numbers = jsonable(numbers)
        figs = self.folder / "figures"
        figs.mkdir(exist_ok=True)
        with _MPL_LOCK:
            if hooks is not None and hooks.figures is not None:
                files = [Path(f) for f in hooks.figures(res, figs)]
            else:
                files = default_figures(res, figs, movie)
        self.figures = [Path(f).name for f in files
                        if Path(f).suffix == ".png" and Path(f).parent == figs]
        self.status = "done"

    def state(self, figure_urls="path") -> dict:
        figures = []
        for n in self.figures:
            if figure_urls == "data":
                import base64
                raw = (self.folder / "figures" / n).read_bytes()
                url = "data:image/png;base64," + base64.b64encode(raw).decode("ascii")
            else:
                url = f"api/run/{self.id}/file/{n}"
            figures.append({"name": n, "url": url})
        res = self.results
        return {"run": self.id, "status": self.status, "progress": round(self.progress, 4),
                "t": self.t, "t_final": self.t_final, "outcome": self.outcome,
                "numbers": self.numbers, "figures": figures,
                "signals": sorted(res.keys()) if res is not None else [],
                "error": self.error}

    def signal(self, name) -> dict:
        import numpy as np
        res = self.results
        if res is None:
            raise EditorError("the run has no results yet", status=404, kind="NotFound")
        if not isinstance(name, str) or name not in res:
            raise EditorError(f"'{name}' was not logged in this run", status=404,
                              kind="NotFound",
                              hint=f"logged: {sorted(res.keys())}; log it with "
                                   "simulation: {log: [...]}")
        v = np.asarray(res[name])
        t = np.asarray(res.t)
        per = max(1, int(np.prod(v.shape[1:])))
        points = max(2, min(MAX_SIGNAL_POINTS, MAX_SIGNAL_VALUES // per))
        step = max(1, -(-len(t) // points))
        idx = np.arange(0, len(t), step)
        if len(t) and idx[-1] != len(t) - 1:
            idx = np.append(idx, len(t) - 1)
        vals = v[idx]
        if vals.dtype.kind == "b":
            vals = vals.astype(int)
        spec = res.ports.get(res._key(name)) if hasattr(res, "ports") else None
        labels = list(getattr(spec, "labels", None) or []) if spec is not None else []
        return {"name": name, "t": t[idx].tolist(),
                "values": np.where(np.isfinite(vals), vals, np.nan).tolist()
                if vals.dtype.kind == "f" else vals.tolist(),
                "shape": list(v.shape[1:]), "labels": [str(x) for x in labels]}

    def figure(self, name) -> Path:
        if not isinstance(name, str) or name not in self.figures:
            raise EditorError(f"no figure '{name}' in this run", status=404,
                              kind="NotFound")
        return self.folder / "figures" / name

    def discard(self):
        shutil.rmtree(self.folder, ignore_errors=True)
