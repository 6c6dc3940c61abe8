"""Runs started from the page: each in a background thread, with progress,
its outcome line, figures and logged signals; :class:`Runs` keeps the last
few and stops them all when the editor closes.

Where a run's files live and how much of it is kept:

* each run writes (its figures, the files its scenario writes) in a folder
  of its own under the editor's folder,
  ``avblocks-out/.editor-<session>/<run>/``, opened through the folder's
  descriptor (:mod:`avblocks.core.confined`); a run's folder is removed
  when the run is dropped from the history, and the session's folder when
  the editor closes (SIGTERM and SIGINT included: ``avblocks edit``);
* when a run ends (done, failed or cancelled) its full log is let go: only
  what the page asks for is kept: the status, the outcome line and numbers,
  the figures (on disk) and each logged signal decimated as the wire plot
  gets it (:data:`MAX_SIGNAL_POINTS` time points, :data:`MAX_SIGNAL_VALUES`
  numbers, at most :data:`MAX_KEPT_VALUES` numbers for all of a run's
  signals together);
* at most :data:`MAX_RUNS` runs are kept (the oldest ended one is dropped
  first) and :data:`MAX_RUNNING` go on at once.
"""

from __future__ import annotations

import contextlib
import gc
import secrets
import threading
from pathlib import Path

from ..core.confined import Confined, FolderError, trim_memory
from ..core.errors import AvError
from .errors import EditorError

#: At most this many time points in a signal sent for the wire plot.
MAX_SIGNAL_POINTS = 2000
#: ... and at most this many numbers in all (agents x components x points).
MAX_SIGNAL_VALUES = 400_000
#: Numbers kept for all the signals of one ended run (8 MB of float64):
#: with many signals, each is decimated further.
MAX_KEPT_VALUES = 1_000_000
#: Runs kept (with their figures) before the oldest finished one is dropped.
MAX_RUNS = 8
#: Runs going on at once; one more is refused (409 ``Busy``).
MAX_RUNNING = 2
#: Largest figure file served (bytes).
MAX_FIGURE_BYTES = 64 * 1024**2
#: Where run folders live under the editor's folder.
RUNS_FOLDER = "avblocks-out"
#: Matplotlib's pyplot state is one per process: figures are drawn one at a time.
MPL_LOCK = threading.Lock()
_COLLECT = threading.Lock()


class RunFolder:
    """A run's own folder under the editor's folder, kept open by descriptor.

    ``path`` names the opened folder for code that takes only paths
    (Matplotlib, the scenario's writers): ``/proc/self/fd/N`` on Linux, so
    that a folder on the way swapped for a symbolic link does not send the
    files elsewhere."""

    def __init__(self, confined: Confined, parts):
        self.confined = confined
        self.parts = tuple(parts)
        self.handle = confined.open_folder(self.parts, create=True)
        self.path = Path(confined.path_of(self.handle, self.parts))
        self.removed = False
        self._writer_done = False
        self._lock = threading.Lock()

    def read(self, parts, limit) -> bytes:
        """The bytes of a file in this folder (no link followed)."""
        if self.removed:
            raise FolderError("the run's folder was removed", kind="NotFound")
        return self.confined.read_bytes(parts, limit, at=self.handle)

    def remove(self, writer_alive=False):
        """Remove the folder with what is in it, and let the descriptor go,
        unless a writer (the run's thread) may still use :attr:`path`: then
        it goes when the writer says it is done (:meth:`writer_done`; its
        number must not be reused under a writer's feet)."""
        with self._lock:
            self.removed = True
            close = not writer_alive or self._writer_done
        with contextlib.suppress(FolderError, OSError):
            self.confined.remove_tree(self.parts)
        if close:
            self._close()

    def writer_done(self):
        """The run's thread writes no more."""
        with self._lock:
            self._writer_done = True
            close = self.removed
        if close:
            self._close()

    def _close(self):
        with self._lock:
            h, self.handle = self.handle, None
        if h is not None:
            self.confined.close_folder(h)


class Runs:
    """The runs of one editor, by id (a random hex string).

    Parameters
    ----------
    confined : Confined
        The editor's folder; run folders are made under
        ``avblocks-out/.editor-<session>/`` in it (when the first run
        starts) and removed by :meth:`close`.
    """

    def __init__(self, confined: Confined):
        self._runs: dict[str, Run] = {}
        self._lock = threading.Lock()
        self._confined = confined
        self.session = (RUNS_FOLDER, f".editor-{secrets.token_hex(4)}")
        self._made_out = None           # whether avblocks-out was made here

    def start(self, data, source, backend, overrides, modules=()) -> str:
        """Start a run of the scenario mapping ``data``; its id."""
        with self._lock:
            running = sum(r.status == "running" for r in self._runs.values())
            if running >= MAX_RUNNING:
                raise EditorError("two runs are going on already; cancel one first",
                                  status=409, kind="Busy")
            self._prune()
            rid = secrets.token_hex(6)
            place = self._place(rid)
            r = Run(rid, data, source, backend, overrides, modules, place=place)
            self._runs[rid] = r
        r.start()
        return rid

    def _place(self, name) -> RunFolder:
        """A new folder ``name`` in this editor's session folder."""
        if self._made_out is None:
            self._made_out = self._confined.stat((RUNS_FOLDER,)) is None
        try:
            return RunFolder(self._confined, (*self.session, name))
        except FolderError as e:
            raise EditorError(f"cannot make a folder for the run: {e}", status=409,
                              kind="FileError") from None

    @contextlib.contextmanager
    def scratch(self):
        """``with runs.scratch() as place``: a folder of its own in the
        session folder (an export's picture), removed after."""
        place = self._place(f"scratch-{secrets.token_hex(6)}")
        try:
            yield place
        finally:
            place.remove()         # the caller's thread is the writer: done

    def _prune(self):
        done = [k for k, r in self._runs.items() if r.status != "running"]
        while len(self._runs) >= MAX_RUNS and done:
            self._runs.pop(done.pop(0)).discard()

    def get(self, run) -> Run:
        """The run with id ``run`` (404 ``NotFound`` if there is none)."""
        r = self._runs.get(str(run))
        if r is None:
            raise EditorError(f"no run '{str(run)[:80]}'", status=404, kind="NotFound")
        return r

    def __len__(self):
        return len(self._runs)

    def close(self):
        """Cancel every run, wait a little for each, remove their folders
        (and ``avblocks-out`` when the editor made it and it is empty)."""
        with self._lock:
            runs = list(self._runs.values())
            self._runs.clear()
        for r in runs:
            r.cancelled = True
        for r in runs:
            if r.thread is not None:
                r.thread.join(5)
            r.discard()
        with contextlib.suppress(FolderError, OSError):
            self._confined.remove_tree(self.session)
        if self._made_out:
            self._confined.remove_empty((RUNS_FOLDER,))


class _Cancelled(KeyboardInterrupt):
    """Raised from a run's progress callback when the page cancels it."""

    signal_name = "cancelled"


class Run:
    """One run of a document in a background thread."""

    def __init__(self, rid, data, source, backend, overrides, modules=(), place=None):
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
        self.kept = None                # the signals kept once the run ended
        self.place = place              # the run's folder (RunFolder)
        self.folder = place.path if place is not None else None

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
        finally:
            self._settle()
            if self.place is not None:
                self.place.writer_done()

    def _settle(self):
        """The run has ended: keep each signal as the wire plot gets it and
        let the full log go (its memory handed back to the system)."""
        res, self.results = self.results, None
        if res is None:
            return
        try:
            names = sorted(res.keys())
            each = max(1, min(MAX_SIGNAL_VALUES, MAX_KEPT_VALUES // max(1, len(names))))
            self.kept = {n: _decimated(res, n, each) for n in names}
        except Exception as e:  # noqa: BLE001 - reported to the page, never raised
            self.kept = {}
            self.error = self.error or f"the run's signals could not be kept: {e}"
        del res
        # the engine's log may sit in a reference cycle (an interrupt's
        # traceback and the frame that holds the log): a full collection
        # frees it. One at a time: CPython skips a collection asked for
        # while another thread's is under way
        with _COLLECT:
            gc.collect()
            trim_memory()

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
                raw = self.figure(n)
                url = "data:image/png;base64," + base64.b64encode(raw).decode("ascii")
            else:
                url = f"api/run/{self.id}/file/{n}"
            figures.append({"name": n, "url": url})
        return {"run": self.id, "status": self.status, "progress": round(self.progress, 4),
                "t": self.t, "t_final": self.t_final, "outcome": self.outcome,
                "numbers": self.numbers, "figures": figures,
                "signals": self._names(), "error": self.error}

    def _names(self) -> list:
        kept, res = self.kept, self.results
        if kept is not None:
            return sorted(kept)
        return sorted(res.keys()) if res is not None else []

    def signal(self, name) -> dict:
        import numpy as np
        kept = self.kept
        if kept is None:
            res = self.results
            if res is None:
                raise EditorError("the run has no results yet", status=404, kind="NotFound")
            if not isinstance(name, str) or name not in res:
                kept = {}
            else:
                kept = {name: _decimated(res, name, MAX_SIGNAL_VALUES)}
        if not isinstance(name, str) or name not in kept:
            raise EditorError(f"'{str(name)[:80]}' was not logged in this run", status=404,
                              kind="NotFound",
                              hint=f"logged: {self._names()}; log it with "
                                   "simulation: {log: [...]}")
        t, vals, shape, labels = kept[name]
        if vals.dtype.kind == "b":
            vals = vals.astype(int)
        return {"name": name, "t": t.tolist(),
                "values": np.where(np.isfinite(vals), vals, np.nan).tolist()
                if vals.dtype.kind == "f" else vals.tolist(),
                "shape": list(shape), "labels": labels}

    def figure(self, name) -> bytes:
        """The PNG bytes of the run's figure ``name`` (read from the run's
        folder, no link followed)."""
        if not isinstance(name, str) or name not in self.figures or self.place is None:
            raise EditorError(f"no figure '{str(name)[:80]}' in this run", status=404,
                              kind="NotFound")
        try:
            return self.place.read(("figures", name), MAX_FIGURE_BYTES)
        except FolderError as e:
            raise EditorError(f"the figure '{name}' cannot be read: {e}", status=404,
                              kind="NotFound") from None

    def discard(self):
        """Let the run's results and its folder go."""
        self.kept = None
        self.results = None
        if self.place is not None:
            alive = self.thread is not None and self.thread.is_alive()
            self.place.remove(writer_alive=alive)


def _decimated(res, name, budget):
    """``(t, values, shape, labels)`` of a logged signal as the wire plot
    gets it: every k-th sample (the last one kept), at most
    :data:`MAX_SIGNAL_POINTS` time points and ``budget`` numbers; copies,
    so the full log can go."""
    import numpy as np
    v = np.asarray(res[name])
    t = np.asarray(res.t)
    per = max(1, int(np.prod(v.shape[1:])))
    points = max(2, min(MAX_SIGNAL_POINTS, budget // per))
    step = max(1, -(-len(t) // points))
    idx = np.arange(0, len(t), step)
    if len(t) and idx[-1] != len(t) - 1:
        idx = np.append(idx, len(t) - 1)
    spec = res.ports.get(res._key(name)) if hasattr(res, "ports") else None
    labels = list(getattr(spec, "labels", None) or []) if spec is not None else []
    return (np.array(t[idx]), np.array(v[idx]), tuple(v.shape[1:]),
            [str(x) for x in labels])
