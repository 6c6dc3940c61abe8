"""``avblocks run``: load a scenario, simulate it under the run guard, write its files.

    avblocks run waypoints --set agents=300 --out out/
    avblocks run my_scenario.yaml
    avblocks run my_diagram.py --set n=50 --set drive.gain=2.0
    avblocks run waypoints --backend jax

Signals, the output folder and atomic writes: :mod:`avblocks._runio`; what
the scenario reports (outcome, figures): :mod:`avblocks.scenarios.report`.
"""

from __future__ import annotations

import sys
from pathlib import Path

from .._runio import (
    Interrupted,
    SignalGuard,
    atomic_path,
    check_memory,
    prepare_output,
    say,
    write_text_atomic,
)
from ..core.errors import AvError, ScenarioError
from ..scenarios.paths import safe_name
from ..scenarios.targets import load_any


def add_parser(sub):
    """The ``run`` sub-command on an argparse sub-parser set."""
    r = sub.add_parser("run", help="run a built-in scenario, a YAML/TOML file or a .py file")
    r.add_argument("target", help="built-in name (see `avblocks list`) or a file")
    r.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a parameter (repeatable), e.g. --set agents=300, "
                        "or a block's numeric parameter: --set drive.gain=2.0")
    r.add_argument("--out", help="output folder (default avblocks-out/<name>)")
    r.add_argument("--movie", help="also write a movie (.mp4 or .gif)")
    r.add_argument("--t-final", type=float, dest="t_final", help="simulated time [s]")
    r.add_argument("--realtime", type=float, help="pace to the wall clock (1.0 = real time)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--live", action="store_true",
                   help="draw and steer the run in the browser (prints the URL)")
    r.add_argument("--live-host", default="127.0.0.1",
                   help="interface for --live (default 127.0.0.1 only)")
    r.add_argument("--live-port", type=int, default=0, help="port for --live (0: free)")
    r.add_argument("--backend", choices=("numpy", "jax"),
                   help="engine: numpy (default) or jax (compiled; pure blocks only)")
    r.add_argument("--no-cache", action="store_true", dest="no_cache",
                   help="jax: neither read nor write the compiled programs and plans "
                        "in the cache folder (also AVBLOCKS_CACHE=off; see "
                        "`avblocks cache`)")
    r.set_defaults(fn=cmd_run)
    return r


def cmd_run(args):
    return guarded_run(args, load_any)


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

    from ..core.errors import SimulationError
    from ..core.frontend import simulate
    from ..scenarios.targets import parse_overrides
    overrides = parse_overrides(args.set)
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
        from ..interfaces.ros2.cli import apply as _robots
        _robots(args, d, sim)
    sim.setdefault("t_final", 10.0)
    if getattr(args, "live", False):  # live view in the browser (avblocks.viz.live)
        sim["live"] = {"host": args.live_host, "port": args.live_port}
    out = prepare_output(args.out or Path("avblocks-out") / safe_name(name))
    movie_path = None
    if args.movie:
        from ..viz.movie import check_movie_path
        movie_path = Path(args.movie)
        if not movie_path.is_absolute() and movie_path.parts[:len(out.parts)] != out.parts:
            movie_path = out / movie_path      # movies land under the output folder
        check_movie_path(movie_path)           # suffix and extra, before simulating
        prepare_output(movie_path.parent)
    check_memory(d, sim)
    cache = _compile_cache(args, sim)
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
        from ..scenarios.report import default_figures
        try:        # the scenario's own figures, else its trajectories
            if hooks is not None and hooks.figures is not None:
                files += [Path(f) for f in hooks.figures(res, out)]
            else:
                files += default_figures(res, out, movie)
        except AvError as e:
            write_errors.append(str(e))
        except OSError as e:        # a Python scenario's own figures() writing itself
            from ..core.atomic import os_reason
            name = f" '{e.filename}'" if getattr(e, "filename", None) else ""
            write_errors.append(f"could not write the figures{name}: {os_reason(e)}")
        if movie_path is not None and interrupted is None and guard.signum is None:
            from ..viz import save_movie
            try:
                with atomic_path(movie_path) as tmp:
                    save_movie(res, tmp, **movie)
                files.append(movie_path)
            except AvError as e:
                write_errors.append(f"movie: {e}")
            except (TypeError, ValueError, KeyError, IndexError, AttributeError) as e:
                write_errors.append(f"movie: a 'movie:' option is wrong: "
                                    f"{type(e).__name__}: {e}")
    from ..scenarios.report import jsonable
    outcome, numbers = None, {}
    if has_samples and interrupted is None and failed is None:
        from ..scenarios.report import default_outcome
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
        "numbers": jsonable(numbers),
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
    if cache is not None:
        summary["compile"] = cache.summary()
    if summary["simulated_s"] and wall > 0:
        summary["realtime_factor"] = round(summary["simulated_s"] / wall, 1)
    if res is not None and "overruns" in res.meta:
        summary["overruns"] = res.meta["overruns"]
        summary["max_lateness_s"] = res.meta.get("max_lateness")
    try:
        files.append(write_text_atomic(out / "summary.json",
                                       json.dumps(summary, indent=2, default=str)))
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
    if cache is not None:
        print(f"compiled program: {cache.line()}")
    if res is not None and "overruns" in res.meta:
        from ..interfaces.ros2.cli import report as _pace_report
        print(_pace_report(res))
    for f in files:
        if Path(f).name != "summary.json":
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
        else:
            say("avblocks: the run finished; kept: "
                + (", ".join(str(f) for f in files) or "nothing"))
        return 3
    return 0


class _CompileCount:
    """What a compiled run of ``avblocks run`` compiled, read from the cache
    folder, or reused (``compiled program:`` in the output)."""

    def __init__(self, root):
        from ..core.compiled.program import COMPILES
        self.root = root
        self.counts = COMPILES
        self.before = dict(COMPILES)

    def summary(self):
        d = {k: self.counts[k] - self.before[k] for k in ("compiled", "from_disk")}
        d["seconds"] = round(self.counts["seconds"] - self.before["seconds"], 3)
        d["cache_dir"] = None if self.root is None else str(self.root)
        return d

    def line(self):
        s = self.summary()
        where = "cache off" if self.root is None else f"cache {self.root}"
        if s["compiled"] == 0 and s["from_disk"]:
            return (f"from cache ({s['from_disk']} read, 0 compiled, "
                    f"{s['seconds']:.2f} s; {where})")
        if s["compiled"] == 0:
            return "none needed"
        return (f"compiled ({s['compiled']} compiled, {s['from_disk']} read from "
                f"cache, {s['seconds']:.2f} s; {where})")


def _compile_cache(args, sim):
    """For ``--backend jax``: the compiled engine keeps its programs and grown
    plans in the user's cache folder by default
    (:mod:`avblocks.core.compiled.persist`); ``--no-cache`` (or
    ``AVBLOCKS_CACHE=off``) runs without it. A counter of the compilations
    to report."""
    if sim.get("backend") != "jax":
        return None
    from ..core.compiled import persist
    if getattr(args, "no_cache", False):
        sim["cache"] = False
    return _CompileCount(persist.usable(persist.resolve(sim.get("cache"))))
