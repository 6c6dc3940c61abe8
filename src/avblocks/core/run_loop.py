"""The NumPy engine's run: :func:`run` steps a :class:`~avblocks.core.simulator.Simulator`
from ``t0`` to ``t_final``, logs the named outputs, paces to the wall clock,
shows progress and returns :class:`~avblocks.core.results.Results`.

It implements the engine contract of :mod:`avblocks.core.frontend` (the
arguments of :func:`avblocks.simulate`, a :class:`Results` back); the checks on
those arguments are the shared run guard (:mod:`avblocks.core.runguard`).
"""

from __future__ import annotations

import math
import time as _time

import numpy as np

from .diagram import PortRef
from .errors import ParameterError, SimulationError
from .params import integer
from .results import Results
from .runguard import (
    _param_binding,
    _progress_wanted,
    default_log,
    finite_number,
    log_every_that_fits,
    progress_bar,
    whole_steps,
)
from .simulator import Simulator

#: a ``progress(step, steps)`` callback is called about 100 times a run and
#: at least this often (wall seconds) in a long one
REPORT_SECONDS = 0.05


def run(diagram, t_final, dt=0.01, solver="rk4", *, log=None, log_every=None, seed=0,
        t0=0.0, realtime=None, progress=None, check_finite=True,
        max_log_bytes=2 * 1024**3, params=None, x0=None, **options):
    """Simulate ``diagram`` with the NumPy engine (arguments and result as
    :func:`avblocks.simulate`; this engine takes no options of its own)."""
    if options:
        raise ParameterError("unknown keyword argument(s) for backend='numpy'",
                             param=", ".join(sorted(options)))
    sim = Simulator(diagram, dt, solver, seed=seed, t0=t0, check_finite=check_finite,
                    x0=x0)
    binding = _param_binding(sim.compiled, params)
    with binding:
        res = run_loop(sim, t_final, log, log_every, realtime, progress, max_log_bytes,
                       params)
    if sim.X is not None:       # the state at the end (as backend="jax" returns it)
        res.final_state = {f"{n}.{k}": v for n, x in zip(sim.compiled.names, sim.X)
                           for k, v in x.items()}
    return res


def run_loop(sim, t_final, log, log_every, realtime, progress, max_log_bytes, params):
    t_final = finite_number(t_final, "t_final")
    nsteps = whole_steps(sim.t0, t_final, sim.dt)
    auto_log = log_every is None       # default: every step, unless too big
    log_every = 1 if auto_log else integer(log_every, None, "log_every", lo=1)
    if realtime is not None and not (finite_number(realtime, "realtime") > 0):
        raise ParameterError("realtime factor must be > 0", param="realtime",
                             expected="> 0", found=realtime)
    report = None
    if callable(progress):          # progress(step, steps) about 100 times a run
        report, progress = progress, False
    if progress is not None and not isinstance(progress, (bool, np.bool_)):
        raise ParameterError("progress must be None, True, False or a callable "
                             "progress(step, steps)", param="progress",
                             found=repr(progress)[:40])
    if isinstance(max_log_bytes, (bool, np.bool_)) or not isinstance(
            max_log_bytes, (int, float, np.integer, np.floating)) or \
            math.isnan(max_log_bytes) or max_log_bytes < 0:
        raise ParameterError("max_log_bytes must be a number of bytes >= 0",
                             param="max_log_bytes", found=repr(max_log_bytes)[:40],
                             hint="float('inf') for no limit")
    if log is None:
        refs = default_log(sim.compiled)
    elif isinstance(log, (str, PortRef)):
        refs = [log]
    elif isinstance(log, (list, tuple)) and all(isinstance(r, (str, PortRef))
                                                 for r in log):
        refs = list(log)
    else:
        raise ParameterError("log must be a port handle, a 'block.port' string or a "
                             "list of them", param="log", found=repr(log)[:60])
    idx, names, specs, aliases = [], [], [], {}
    for r in refs:
        i, o = sim.compiled.resolve(r)
        name = f"{sim.compiled.names[i]}.{o}"
        if name in names:
            continue
        idx.append((i, o))
        names.append(name)
        specs.append(sim.compiled.blocks[i]._outputs[o])
        alias = r.path if isinstance(r, PortRef) else str(r)
        if alias != name:
            aliases[alias] = name
    nlog = nsteps // log_every + 1
    need = sum(nlog * int(np.prod(p.shape)) * np.dtype(p.dtype).itemsize for p in specs)
    if need > max_log_bytes:
        fit = log_every_that_fits(need // nlog, nsteps, max_log_bytes)
        if auto_log and fit is not None:
            import warnings
            warnings.warn(f"logging every step would take {need / 1e9:.2f} GB (more than "
                          f"max_log_bytes = {max_log_bytes / 1e9:.2f} GB): logging one step in "
                          f"{fit} instead (log_every={fit}; pass log_every= or "
                          "max_log_bytes= to choose)", stacklevel=3)
            log_every = fit
            nlog = nsteps // log_every + 1
        else:
            raise ParameterError(
                f"the log would take {need / 1e9:.2f} GB", param="log",
                expected=f"<= {max_log_bytes / 1e9:.2f} GB",
                found=f"{len(specs)} signals x {nlog} samples",
                hint=(f"log_every={fit} fits (or log fewer signals, or raise "
                      "max_log_bytes)" if fit is not None else
                      "log fewer signals: even two samples do not fit"))
    try:
        bufs = [np.empty((nlog, *p.shape), dtype=p.dtype) for p in specs]
        tlog = np.empty(nlog)
    except (MemoryError, ValueError):
        raise ParameterError(f"the log ({need / 1e9:.3g} GB) does not fit in memory",
                             param="log", hint="log fewer signals or decimate with "
                                                "log_every") from None
    meta = {"solver": sim.solver.name, "dt": sim.dt, "seed": sim.seed,
            "t0": sim.t0, "t_final": sim.t0 + nsteps * sim.dt,
            "log_every": log_every, "steps": nsteps,
            "agents": max([p.n or 0 for p in specs] + [0]),
            "blocks": len(sim.compiled.blocks)}
    if params:
        meta["params"] = {str(k): np.asarray(v, float).tolist() for k, v in params.items()}
    meta["param_changes"] = sim.param_changes
    count = 0

    logged_float = [(i, o) for (i, o), p in zip(idx, specs)
                    if np.issubdtype(np.dtype(p.dtype), np.inexact)]

    def record():
        nonlocal count
        sim.check_outputs(sim.t, logged_float)
        for b, (i, o) in zip(bufs, idx):
            b[count] = sim.Y[i][o]
        tlog[count] = sim.t
        count += 1

    def partial():
        return Results(tlog[:count].copy(), {n: b[:count].copy()
                                             for n, b in zip(names, bufs)},
                       dict(zip(names, specs)), meta, aliases)

    bar = None
    if _progress_wanted(progress) and nsteps > 0:
        bar = progress_bar(nsteps)
    pace = None if realtime is None else float(realtime)
    overruns, worst = 0, 0.0
    wall0 = _time.perf_counter()
    sim.horizon = nsteps
    failure = interrupt = None
    try:
        try:
            sim.init()
            record()
            # pace from the end of init: on_start may connect to robots first
            pace0 = _time.perf_counter()
            tick = max(1, nsteps // 100)
            # ... and at least every REPORT_SECONDS of wall time: a stop
            # raised from the callback lands that soon in a long run
            next_report = _time.perf_counter() + REPORT_SECONDS
            for k in range(nsteps):
                sim.step()
                if (k + 1) % log_every == 0:
                    record()
                if pace is not None:
                    target = pace0 + (k + 1) * sim.dt / pace
                    now = _time.perf_counter()
                    if now < target:
                        _time.sleep(target - now)
                    else:
                        late = now - target
                        worst = max(worst, late)
                        if late > sim.dt / pace:
                            overruns += 1
                if (k + 1) % tick == 0:
                    if bar is not None:
                        bar.update(tick)
                    if report is not None:
                        report(k + 1, nsteps)
                        next_report = _time.perf_counter() + REPORT_SECONDS
                elif report is not None and _time.perf_counter() >= next_report:
                    report(k + 1, nsteps)
                    next_report = _time.perf_counter() + REPORT_SECONDS
        except SimulationError as e:
            failure = e
        except KeyboardInterrupt as e:
            interrupt = e
        finally:
            if bar is not None:
                bar.close()
        stop_failures = sim.close()
    except KeyboardInterrupt as e:   # landed between the loop and close()
        interrupt = interrupt or e
        stop_failures = []
    for _name, e in stop_failures:
        if isinstance(e, KeyboardInterrupt) and interrupt is None:
            interrupt = e
    stop_errors = [f"block '{n}' on_stop: {type(e).__name__}: {e}"
                   for n, e in stop_failures if not isinstance(e, KeyboardInterrupt)]
    wall = _time.perf_counter() - wall0
    meta["wall_time"] = wall
    if stop_errors:
        meta["on_stop_errors"] = stop_errors
    if failure is not None:
        meta["error"] = str(failure)
        failure.results = partial()
        failure.on_stop_errors = stop_errors
        if stop_errors:
            failure.add_note("also, while stopping: " + "; ".join(stop_errors))
        raise failure
    if interrupt is not None:
        meta["interrupted_at"] = sim.t
        meta["interrupted"] = True
        meta["interrupted_by"] = getattr(interrupt, "signal_name", "SIGINT")
    else:
        meta["realtime_factor"] = (nsteps * sim.dt / wall) if wall > 0 else math.inf
    if pace is not None:
        meta["overruns"] = overruns
        meta["max_lateness"] = worst
    if hasattr(sim.solver, "nfev"):
        meta["nfev"] = sim.solver.nfev
    if stop_errors:
        import warnings

        from .errors import SimulationWarning
        warnings.warn("the run finished and its results are returned, but "
                      + "; ".join(stop_errors), SimulationWarning, stacklevel=3)
    if count < nlog:
        return partial()
    return Results(tlog, dict(zip(names, bufs)), dict(zip(names, specs)), meta,
                   aliases)
