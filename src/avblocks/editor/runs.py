"""Runs started from the page: each in a background thread, with progress,
its outcome line, figures and logged signals; :class:`Runs` keeps the last
few and stops them all when the editor closes.
"""

from __future__ import annotations

import secrets
import shutil
import tempfile
import threading
from pathlib import Path

from ..core.errors import AvError
from .errors import EditorError

#: At most this many time points in a signal sent for the wire plot.
MAX_SIGNAL_POINTS = 2000
#: ... and at most this many numbers in all (agents x components x points).
MAX_SIGNAL_VALUES = 400_000
#: Runs kept (with their figures) before the oldest finished one is dropped.
MAX_RUNS = 8
#: Runs going on at once; one more is refused (409 ``Busy``).
MAX_RUNNING = 2
#: Matplotlib's pyplot state is one per process: figures are drawn one at a time.
MPL_LOCK = threading.Lock()


class Runs:
    """The runs of one editor, by id (a random hex string)."""

    def __init__(self):
        self._runs: dict[str, Run] = {}
        self._lock = threading.Lock()

    def start(self, data, source, backend, overrides, modules=()) -> str:
        """Start a run of the scenario mapping ``data``; its id."""
        with self._lock:
            running = sum(r.status == "running" for r in self._runs.values())
            if running >= MAX_RUNNING:
                raise EditorError("two runs are going on already; cancel one first",
                                  status=409, kind="Busy")
            self._prune()
            rid = secrets.token_hex(6)
            r = Run(rid, data, source, backend, overrides, modules)
            self._runs[rid] = r
        r.start()
        return rid

    def _prune(self):
        done = [k for k, r in self._runs.items() if r.status != "running"]
        while len(self._runs) >= MAX_RUNS and done:
            self._runs.pop(done.pop(0)).discard()

    def get(self, run) -> Run:
        """The run with id ``run`` (404 ``NotFound`` if there is none)."""
        r = self._runs.get(str(run))
        if r is None:
            raise EditorError(f"no run '{run}'", status=404, kind="NotFound")
        return r

    def close(self):
        """Cancel every run, wait a little for each, remove their folders."""
        for r in list(self._runs.values()):
            r.cancelled = True
        for r in list(self._runs.values()):
            if r.thread is not None:
                r.thread.join(5)
            r.discard()
        self._runs.clear()


class _Cancelled(KeyboardInterrupt):
    """Raised from a run's progress callback when the page cancels it."""

    signal_name = "cancelled"


class Run:
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
        overrides = dict(self.overrides)
        figures = overrides.pop("figures", True)
        sim.update(overrides)
        sim.setdefault("t_final", 10.0)
        self.t_final = float(sim["t_final"])
        if self.backend == "jax":
            # the compiled run goes in segments that report (and can be
            # stopped) between them: core.compiled.segments
            sim["backend"] = "jax"
        sim["progress"] = self._tick
        if self.cancelled:            # cancelled while it was being built
            self.status = "cancelled"
            return
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
        if not figures:             # a quick re-run (the page's sliders)
            self.status = "done"
            return
        figs = self.folder / "figures"
        figs.mkdir(exist_ok=True)
        with MPL_LOCK:
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
