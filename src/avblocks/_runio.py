"""What keeps an ``avblocks run`` from losing data: signals, the output folder,
atomic files.

* :class:`SignalGuard` turns the first SIGINT, SIGTERM or SIGHUP into an
  :class:`Interrupted` (a ``KeyboardInterrupt``), which :func:`simulate`
  catches to return what it logged so far; every later signal is only
  noted while the results are written, so a second Ctrl-C never loses them.
  The exit status is then ``128 + signal number`` (130, 143, 129).
* :func:`prepare_output` makes the output folder and proves it writable
  before anything is simulated.
* :func:`atomic_path` gives a temporary name next to the target, renamed
  into place only when the writer finished: a full disk or an interrupt
  never leaves a half-written file under the real name.
* :func:`inside` checks that a path a scenario file names stays inside a
  folder (no absolute paths, no ``..`` out of it).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import tempfile
from pathlib import Path

from .core.errors import AvError, ScenarioError

_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP")
                 if hasattr(signal, n))


class Interrupted(KeyboardInterrupt):
    """The run was stopped by a signal; ``signum`` and ``signal_name`` say which."""

    def __init__(self, signum):
        self.signum = int(signum)
        self.signal_name = signal.Signals(signum).name
        super().__init__(self.signal_name)


class SignalGuard:
    """Context manager for the whole of a CLI run.

    While *armed*, the first signal raises :class:`Interrupted` in the main
    thread; after that (or after :meth:`defer`, called once the simulation
    returned) signals are only recorded, so writing the files finishes.
    ``signum`` is the first signal received (or None); ``exit_code`` is
    ``128 + signum``.
    """

    def __init__(self):
        self.signum = None
        self.armed = True
        self._old = {}

    def _handler(self, signum, frame):
        first = self.signum is None
        if first:
            self.signum = signum
        if first and self.armed:
            self.armed = False
            raise Interrupted(signum)
        try:
            os.write(2, b"avblocks: still writing what was simulated; "
                        b"it will stop right after\n")
        except OSError:
            pass

    def defer(self):
        """From now on signals are recorded, never raised."""
        self.armed = False

    @property
    def exit_code(self):
        return None if self.signum is None else 128 + int(self.signum)

    @property
    def signal_name(self):
        return None if self.signum is None else signal.Signals(self.signum).name

    def __enter__(self):
        import threading
        if threading.current_thread() is threading.main_thread():
            for s in _SIGNALS:
                try:
                    self._old[s] = signal.signal(s, self._handler)
                except (OSError, ValueError):  # pragma: no cover - exotic platforms
                    pass
        return self

    def __exit__(self, *exc):
        for s, h in self._old.items():
            signal.signal(s, h)
        return False


def prepare_output(out) -> Path:
    """Create the output folder and prove it writable (a temporary file is
    made and removed), before anything is simulated."""
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise AvError(f"output folder '{out}' exists and is not a folder",
                      hint="pass another --out") from None
    except OSError as e:
        raise AvError(f"cannot create the output folder '{out}': "
                      f"{e.strerror or e}", hint="pass a writable --out") from None
    if not out.is_dir():
        raise AvError(f"output folder '{out}' is not a folder", hint="pass another --out")
    try:
        fd, probe = tempfile.mkstemp(prefix=".avblocks-probe-", dir=out)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise AvError(f"the output folder '{out}' is not writable: {e.strerror or e}",
                      hint="pass a writable --out (nothing was simulated)") from None
    return out


@contextlib.contextmanager
def atomic_path(path):
    """``with atomic_path(p) as tmp: write(tmp)``: ``tmp`` is renamed to ``p``
    when the block succeeds, removed when it fails (an OSError becomes an
    :class:`AvError` naming ``p``)."""
    from .core.results import _os_reason
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".part{path.suffix}",
                               dir=path.parent)
    from .core.results import _umask
    os.fchmod(fd, 0o666 & ~_umask())
    os.close(fd)
    ok = False
    try:
        yield Path(tmp)
        os.replace(tmp, path)
        ok = True
    except OSError as e:
        raise AvError(f"could not write '{path}': {_os_reason(e)}") from None
    finally:
        if not ok:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def write_text_atomic(path, text):
    from .core.results import atomic_write_bytes
    return atomic_write_bytes(path, text.encode())


def inside(path, folder, *, what, source=None, must_exist=False) -> Path:
    """``path`` resolved against ``folder``; a :class:`ScenarioError` when it
    leaves ``folder`` (absolute elsewhere, ``..``, a symbolic link out)."""
    folder = Path(folder).resolve()
    p = Path(os.path.expanduser(str(path))) if str(path).startswith("~") else Path(str(path))
    full = (folder / p).resolve()
    if full != folder and folder not in full.parents:
        raise ScenarioError(f"'{path}' is outside the folder '{folder}'",
                            file=source, entry=what,
                            hint="a scenario file may only write inside the output "
                                 "folder and read files under its own folder")
    if must_exist and not full.is_file():
        raise ScenarioError(f"'{path}' is not a file", file=source, entry=what)
    return full


def say(msg):
    """One line on stderr, never raising (stderr may be closed)."""
    with contextlib.suppress(OSError, ValueError):
        print(msg, file=sys.stderr, flush=True)


def estimate_bytes(compiled, sim) -> int:
    """Memory a run needs, estimated from the declared ports before anything
    is allocated: states and outputs (about six copies of the states for
    the solver stages and two of the outputs) plus the log."""
    import numpy as np
    state = sum(np.asarray(v).nbytes for b in compiled.blocks for v in b._init.values())
    outs = sum(int(np.prod(p.shape)) * np.dtype(p.dtype).itemsize
               for b in compiled.blocks for p in b._outputs.values()
               if p.shape is not None)
    need = 6 * state + 2 * outs
    try:
        dt = float(sim.get("dt", 0.01))
        steps = (float(sim.get("t_final", 10.0)) - float(sim.get("t0", 0.0))) / dt
        every = max(1, int(sim.get("log_every") or 1))
        if np.isfinite(steps) and steps > 0:
            from .core.runguard import default_log
            log = sim.get("log") or default_log(compiled)
            log = [log] if isinstance(log, str) else list(log)
            per = 0
            for r in log:
                i, o = compiled.resolve(r)
                p = compiled.blocks[i]._outputs[o]
                per += int(np.prod(p.shape)) * np.dtype(p.dtype).itemsize
            log_bytes = int(steps // every + 1) * per
            if sim.get("log_every") is None:     # simulate() decimates to the cap
                log_bytes = min(log_bytes, int(sim.get("max_log_bytes", 2 * 1024**3)))
            need += log_bytes
    except (TypeError, ValueError, OverflowError, AvError):
        pass            # simulate() names the bad setting itself
    return int(need)


def check_memory(diagram, sim):
    """Refuse, before simulating, a run whose estimate passes the memory
    limit (``AVBLOCKS_MAX_MEMORY``), with the figure."""
    from .scenarios.loader import memory_limit
    need = estimate_bytes(diagram.build(), sim)
    lim = memory_limit()
    if need > lim:
        raise AvError(f"this run would need about {need / 1e9:.3g} GB "
                      f"(states, outputs and log)",
                      expected=f"<= {lim / 1e9:.3g} GB (AVBLOCKS_MAX_MEMORY)",
                      hint="use fewer agents, a shorter run, or decimate the log "
                           "(--set simulation.log_every=10)")


def safe_name(name) -> str:
    """A scenario name made safe as one folder name (no separators, no
    leading dots): it names ``avblocks-out/<name>`` when ``--out`` is not given."""
    import re
    s = re.sub(r"[^A-Za-z0-9_.-]+", "_", str(name)).lstrip(".")
    return s[:100] or "scenario"


def guarded_run(args, load_any):
    """``avblocks run``: load, prove the output writable, simulate under a
    :class:`SignalGuard`, then write every file atomically. Exit status: 0
    done, 2 bad input, 3 the run failed (partial results saved when any),
    128 + signal number when a signal stopped it."""
    with SignalGuard() as guard:
        try:
            return _guarded_run(args, guard, load_any)
        except Interrupted as e:
            say(f"avblocks: interrupted by {e.signal_name} before anything was "
                "simulated; nothing was written")
            return 128 + e.signum


def _guarded_run(args, guard, load_any):
    import json
    import time

    from .cli import _parse_sets
    from .core.errors import SimulationError
    from .core.frontend import simulate
    overrides = _parse_sets(args.set)
    loaded = load_any(args.target, overrides, args.out)
    d, sim, name, movie = loaded
    hooks = getattr(loaded, "hooks", None)
    if args.realtime is not None:
        sim["realtime"] = args.realtime
    if args.t_final is not None:
        sim["t_final"] = args.t_final
    if getattr(args, "backend", None) is not None:   # compiled: avblocks.core.compiled
        sim["backend"] = args.backend
    if getattr(args, "robots", None):  # on ROS 2 robots (extra [ros2])
        from .interfaces.ros2.cli import apply as _robots
        _robots(args, d, sim)
    sim.setdefault("t_final", 10.0)
    if getattr(args, "live", False):  # live view in the browser (avblocks.viz.live)
        sim["live"] = {"host": args.live_host, "port": args.live_port}
    out = prepare_output(args.out or Path("avblocks-out") / safe_name(name))
    movie_path = None
    if args.movie:
        from .viz.movie import check_movie_path
        movie_path = Path(args.movie)
        if not movie_path.is_absolute() and movie_path.parts[:len(out.parts)] != out.parts:
            movie_path = out / movie_path      # movies land under the output folder
        check_movie_path(movie_path)           # suffix and extra, before simulating
        prepare_output(movie_path.parent)
    check_memory(d, sim)
    t0 = time.perf_counter()
    failed = None
    res = None
    try:
        res = simulate(d, progress=None if not args.quiet else False, **sim)
    except SimulationError as e:
        failed = e
        res = e.results
    except TypeError as e:
        raise ScenarioError(f"bad simulation settings: {e}", entry="simulation") from None
    except Interrupted:
        raise
    guard.defer()
    wall = time.perf_counter() - t0
    interrupted = None
    if res is not None and res.meta.get("interrupted"):
        interrupted = res.meta.get("interrupted_by", "SIGINT")
    files, write_errors = [], []
    saved_results = None
    has_samples = res is not None and len(res.t) > 0
    if has_samples:
        try:
            saved_results = res.save(out / "results.nc")
            files.append(saved_results)
        except AvError as e:
            write_errors.append(str(e))
        from .scenarios.report import default_figures
        try:        # the scenario's own figures, else its trajectories
            if hooks is not None and hooks.figures is not None:
                files += [Path(f) for f in hooks.figures(res, out)]
            else:
                files += default_figures(res, out, movie)
        except AvError as e:
            write_errors.append(str(e))
        if movie_path is not None and interrupted is None and guard.signum is None:
            from .viz import save_movie
            try:
                with atomic_path(movie_path) as tmp:
                    save_movie(res, tmp, **movie)
                files.append(movie_path)
            except AvError as e:
                write_errors.append(f"movie: {e}")
    from .scenarios.report import _jsonable
    outcome, numbers = None, {}
    if has_samples and interrupted is None and failed is None:
        from .scenarios.report import default_outcome
        if hooks is not None and hooks.outcome is not None:
            outcome, numbers = hooks.outcome(res)
        else:
            outcome, numbers = default_outcome(res)
    if interrupted is None and guard.signum is not None:
        interrupted = guard.signal_name
    summary = {
        "scenario": name,
        "status": ("interrupted" if interrupted else "failed" if failed is not None
                   else "complete"),
        "agents": res.meta.get("agents") if res is not None else None,
        "simulated_s": float(res.t[-1] - res.t[0]) if has_samples else 0.0,
        "wall_s": round(wall, 3),
        "realtime_factor": None,
        "outcome": outcome,
        "numbers": _jsonable(numbers),
        "files": [str(f) for f in files],
    }
    if interrupted:
        summary["interrupted_by"] = interrupted
    if failed is not None:
        summary["error"] = str(failed)
    if res is not None and res.meta.get("on_stop_errors"):
        summary["on_stop_errors"] = res.meta["on_stop_errors"]
    if failed is not None and getattr(failed, "on_stop_errors", None):
        summary["on_stop_errors"] = failed.on_stop_errors
    if write_errors:
        summary["write_errors"] = write_errors
    if summary["simulated_s"] and wall > 0:
        summary["realtime_factor"] = round(summary["simulated_s"] / wall, 1)
    if res is not None and "overruns" in res.meta:
        summary["overruns"] = res.meta["overruns"]
        summary["max_lateness_s"] = res.meta.get("max_lateness")
    try:
        write_text_atomic(out / "summary.json", json.dumps(summary, indent=2, default=str))
    except AvError as e:
        write_errors.append(str(e))
    print(f"scenario      {name}")
    print(f"status        {summary['status']}"
          + (f" ({interrupted})" if interrupted else ""))
    print(f"agents        {summary['agents']}")
    print(f"simulated     {summary['simulated_s']:.3g} s")
    print(f"wall time     {wall:.3g} s")
    if summary["realtime_factor"] is not None:
        print(f"real-time x   {summary['realtime_factor']}")
    if res is not None and "overruns" in res.meta:
        from .interfaces.ros2.cli import report as _pace_report
        print(_pace_report(res))
    for f in files:
        print(f"wrote         {f}")
    if outcome:
        print(f"outcome       {outcome}")
    sys.stdout.flush()
    for e in summary.get("on_stop_errors", []):
        say(f"avblocks: error while stopping: {e}")
    for e in write_errors:
        say(f"avblocks: error: {e}")
    if saved_results is not None:
        kept = f"results up to t={res.t[-1]:.6g} were saved to {saved_results}"
    elif has_samples:
        kept = "the results could NOT be saved (see above)"
    else:
        kept = "nothing had been logged, so nothing was saved"
    if interrupted:
        say(f"avblocks: interrupted by {interrupted}; {kept}")
        return guard.exit_code or 130
    if failed is not None:
        say(f"avblocks: error: {failed} ({kept})")
        return 3
    if write_errors or summary.get("on_stop_errors"):
        if saved_results is None and has_samples:
            say(f"avblocks: the run finished but {kept}")
        return 3
    return 0
