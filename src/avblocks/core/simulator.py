"""Running a diagram: :class:`Simulator` (step by hand) and :func:`simulate`.

The major step
--------------
With major step ``h`` and ``t_k = t0 + k h``, the simulator does::

    init:   X <- initial states (random keys seeded from seed and block path)
            Y <- outputs of every block at t0          (initial outputs)
            side effects at t0; log k = 0
    repeat for k = 0 .. K-1:
        1. X <- discrete updates at t_k, from X and Y:
               continuous-time blocks with discrete states: every step;
               periodic blocks: only at their hits.
        2. X <- solver advances continuous states from t_k to t_k+1,
               with k1 = f(t_k, X, Y); later stages recompute the outputs
               of continuous blocks; periodic blocks hold theirs.
        3. Y <- outputs at t_k+1 in sorted order; a periodic block recomputes
               its outputs only at a hit and holds them otherwise.
        4. check the float states are finite (if not, blame the first
           non-finite output in evaluation order, else the state); side
           effects (on_major_step) at t_k+1; log every ``log_every`` steps
           (logged outputs are checked too); pace to the wall clock.

With a variable-step solver, step 2 may run one adaptive solve across
several major steps when no discrete state can change in between (only
periodic blocks have discrete states and none hits); steps 3-4 still
happen at every major step, from the solver's states on the grid.

So a discrete block's output at a hit uses its state before that hit's
update (outputs, then updates), its value is held until its next hit, and
a continuous block sees the discrete value through the whole step.
"""

from __future__ import annotations

import math
import os
import sys
import threading
import time as _time

import numpy as np

from . import rng as _rng
from .diagram import CompiledDiagram, Diagram, PortRef
from .engine import Engine
from .errors import AvError, ParameterError, ShapeError, SimulationError
from .results import Results
from .solvers import make_solver


class Simulator:
    """Steps a diagram by hand; :func:`simulate` wraps it.

    Parameters
    ----------
    diagram : Diagram or CompiledDiagram
    dt : float
        Major step (fixed-step solvers integrate with it; variable-step
        solvers restart at each major step).
    solver : str or Solver
        ``"rk4"`` (default), ``"euler"``, or a :func:`scipy.integrate.solve_ivp`
        method (``"RK45"``, ``"DOP853"``, ``"LSODA"``...) or a Solver object.
    seed : int
        Seeds every random-key state; same seed, same run, bit for bit.
    t0 : float
        Start time.
    check_finite : bool
        Stop with :class:`SimulationError` at the first NaN or inf.
    x0 : dict, optional
        Initial values of states by ``"block.state"`` (default: the blocks'
        declared initial values).

    Numeric parameters (``"block.name"``, see :meth:`Block.declare_parameter`)
    are read with :meth:`get_param` and changed with :meth:`set_param`,
    also from another thread (a live view): a change takes effect at the
    start of the next major step and is recorded in :attr:`param_changes`.

    Example
    -------
    >>> import avblocks as av
    >>> d = av.Diagram()
    >>> c = d.add(av.blocks.Constant([[1.0]]), name="c")
    >>> i = d.add(av.blocks.Integrator([[0.0]]), name="i")
    >>> d.connect(c.y, i.u)
    >>> sim = av.Simulator(d, dt=0.1)
    >>> for _ in range(10):
    ...     sim.step()
    >>> round(float(sim.value(i.y)[0, 0]), 12)
    1.0
    """

    def __init__(self, diagram, dt=0.01, solver="rk4", *, seed=0, t0=0.0,
                 check_finite=True, x0=None):
        if isinstance(diagram, Diagram):
            diagram = diagram.build()
        if not isinstance(diagram, CompiledDiagram):
            raise ParameterError("simulate needs a Diagram", param="diagram",
                                 expected="Diagram", found=type(diagram).__name__)
        self.compiled = diagram
        try:
            dt = float(dt)
        except (TypeError, ValueError):
            dt = float("nan")
        if not (math.isfinite(dt) and dt > 0):
            raise ParameterError("major step must be a positive number",
                                 param="dt", expected="> 0", found=dt)
        self.dt = dt
        self.solver = make_solver(solver)
        self.seed = int(seed)
        self.t0 = float(t0)
        self.check_finite = bool(check_finite)
        self.eng = Engine(diagram, dt)
        self._fx = [(i, o) for i in self.eng.with_outputs
                    for o, p in diagram.blocks[i]._outputs.items()
                    if np.issubdtype(np.dtype(p.dtype), np.inexact)]
        self._fx_state = [(i, nm) for i in self.eng.cont
                          for nm in self.eng.cont_names[i]]
        self._fx_dstate = [(i, nm) for i in self.eng.disc
                           for nm, p in diagram.blocks[i]._dstates.items()
                           if np.issubdtype(np.dtype(p.dtype), np.inexact)]
        self._side = [i for i, b in enumerate(diagram.blocks) if b.side_effects]
        # variable-step solvers may integrate across several major steps when
        # only periodic blocks have discrete states and nothing has side effects
        self._span = (not self.solver.fixed_step and hasattr(self.solver, "integrate")
                      and all(self.eng.periodic[i] for i in self.eng.disc)
                      and not self._side)
        self.horizon = None     # last step index, set by simulate(); enables spans
        self.x0 = self._check_x0(x0)
        self._pending = []      # parameter changes waiting for the next major step
        self._lock = threading.Lock()
        #: ``[(t, "block.name", value as list)]``: changes made during the run.
        self.param_changes = []
        self._queue = []
        self.k = 0
        self.X = None
        self.Y = None

    # --------------------------------------------------------------- state
    @property
    def t(self) -> float:
        return self.t0 + self.k * self.dt

    def _check_x0(self, x0):
        out = {}
        if x0 is None:
            return out
        if not isinstance(x0, dict):
            raise ParameterError("x0 must be a dict {'block.state': value}", param="x0",
                                 found=type(x0).__name__)
        for path, v in x0.items():
            bpath, _, nm = str(path).rpartition(".")
            i = self.compiled.index(bpath) if bpath else self.compiled.index(str(path))
            b = self.compiled.blocks[i]
            if nm not in b._init or nm in b._random:
                raise ParameterError("no such state", block=bpath, param=nm,
                                     expected=sorted(set(b._init) - b._random), found=nm)
            old = b._init[nm]
            try:
                a = np.array(v, dtype=old.dtype)
            except (TypeError, ValueError):
                raise ParameterError("initial value must be numeric", block=bpath,
                                     param=nm, found=repr(v)[:60]) from None
            if a.shape != old.shape:
                raise ParameterError("initial value has the wrong shape", block=bpath,
                                     param=nm, expected=old.shape, found=a.shape)
            if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
                raise ParameterError("initial value must be finite", block=bpath,
                                     param=nm)
            out[(i, nm)] = a
        return out

    # ---------------------------------------------------------- parameters
    def get_param(self, path):
        """Current value of the numeric parameter ``"block.name"``."""
        return self.compiled.get_param(path)

    def set_param(self, path, value):
        """Change the numeric parameter ``"block.name"``: validated now,
        applied at the start of the next major step (at once before
        :meth:`init`). Thread-safe."""
        i, name = self.compiled.param_index(path)
        blk = self.compiled.blocks[i]
        a = blk._params[name].validate(value, self.compiled.names[i])
        if self.X is None:
            blk.__dict__[name] = a
            return
        with self._lock:
            self._pending.append((str(path), blk, name, a))

    def _apply_pending(self):
        with self._lock:
            pending, self._pending = self._pending, []
        for path, blk, name, a in pending:
            blk.__dict__[name] = a
            self.param_changes.append((self.t, path, a.tolist()))

    def initial_states(self):
        X = []
        for j, (name, b) in enumerate(zip(self.compiled.names, self.compiled.blocks)):
            x = b.initial_state()
            for (i, nm), v in self.x0.items():
                if i == j:
                    x[nm] = v.copy()
            for r in b._random:
                x[r] = _rng.key(self.seed, f"{name}.{r}")
            X.append(x)
        return X

    def init(self):
        """Reset to ``t0``: initial states, initial outputs, side effects."""
        self.k = 0
        self._queue = []
        self.X = self.initial_states()
        Y0 = [dict() for _ in self.compiled.blocks]
        self.Y = self._guard(self.eng.all_outputs, self.t0, self.X, Y0)
        self._check_declared()
        self._check(self.t0)
        self.check_outputs(self.t0)
        for i in self._side:
            self.compiled.blocks[i].on_start()
        self._side_effects()
        return self

    def _check_declared(self):
        """First outputs must have the declared shapes and dtypes."""
        for i, b in enumerate(self.compiled.blocks):
            y = self.Y[i]
            for o, p in b._outputs.items():
                if o not in y:
                    raise ShapeError("output() did not return this port",
                                     block=self.compiled.names[i], port=o,
                                     expected=sorted(b._outputs), found=sorted(y))
                a = np.asarray(y[o])
                if a.shape != p.shape:
                    raise ShapeError("output() returned the wrong shape",
                                     block=self.compiled.names[i], port=o,
                                     expected=p.shape, found=a.shape)
                if a.dtype.kind != np.dtype(p.dtype).kind:
                    raise ShapeError("output() returned the wrong dtype",
                                     block=self.compiled.names[i], port=o,
                                     expected=p.dtype, found=a.dtype.name)

    def _guard(self, fn, t, *args):
        try:
            return fn(t, *args)
        except AvError:
            raise
        except Exception as e:  # noqa: BLE001 - add the block context
            raise self._wrap(e, t) from e

    def _wrap(self, e, t):
        """A SimulationError naming the block whose code raised ``e``."""
        name = _blame(e, self.compiled)
        hint = None
        if isinstance(e, KeyError):
            hint = ("output() only receives inputs declared with "
                    "feedthrough=True; derivative() and update() receive all")
        return SimulationError(f"{type(e).__name__}: {e}", block=name, time=t,
                               hint=hint)

    def _check(self, t):
        """Stop at the first non-finite value. Every step checks the float
        states (one reduction each); when one is bad, the outputs are scanned
        in evaluation order to blame the first block and port that produced
        a NaN/inf. Logged outputs are checked when they are recorded."""
        if not self.check_finite:
            return
        X = self.X
        for i, nm in self._fx_state:
            if not math.isfinite(X[i][nm].sum()):
                self._blame_nonfinite(t, (i, nm))
        for i, nm in self._fx_dstate:
            if not math.isfinite(X[i][nm].sum()):
                self._blame_nonfinite(t, (i, nm))

    def check_outputs(self, t, ports=None):
        """Raise if any of ``ports`` ([(block index, name)], default all float
        outputs) is non-finite, naming the first in evaluation order."""
        if not self.check_finite:
            return
        Y = self.Y
        for i, o in (self._fx if ports is None else ports):
            if not math.isfinite(np.asarray(Y[i][o]).sum()):
                self._blame_nonfinite(t, None)

    def _blame_nonfinite(self, t, state):
        for i, o in self._fx:
            if not np.all(np.isfinite(self.Y[i][o])):
                raise SimulationError("output is NaN or infinite",
                                      block=self.compiled.names[i], port=o, time=t)
        if state is not None:
            i, nm = state
            raise SimulationError(
                f"state '{nm}' became NaN or infinite (its derivative or update "
                "produced it)", block=self.compiled.names[i], time=t)

    def _side_effects(self):
        for i in self._side:
            b = self.compiled.blocks[i]
            b.on_major_step(self.t, self.X[i], self.eng.gather(i, self.Y), self.Y[i])

    def step(self):
        """One major step: updates at t_k, integrate to t_k+1, outputs at t_k+1."""
        if self.X is None:
            self.init()
        eng, k, h = self.eng, self.k, self.dt
        if self._pending:
            # new values hold from t_k on: outputs at t_k are recomputed with
            # them (periodic blocks only at a hit), and a span assumed the old
            self._apply_pending()
            self._queue = []
            self.Y = self._guard(eng.major_outputs, self.t, self.X, self.Y, eng.hits(k))
        t = self.t0 + k * h
        t1 = self.t0 + (k + 1) * h
        try:
            if self._queue:                  # inside a span: no discrete event
                X = self._queue.pop()
            else:
                X = eng.update(t, self.X, self.Y, eng.hits(k))
                end = self._span_end(k)
                if end > k + 1:
                    times = [self.t0 + j * h for j in range(k + 1, end + 1)]
                    states = self.solver.integrate(eng, t, X, self.Y, times)
                    self._queue = states[::-1]
                    X = self._queue.pop()
                else:
                    X = self.solver.step(eng, t, X, self.Y, h)
            Y = eng.major_outputs(t1, X, self.Y, eng.hits(k + 1))
        except AvError:
            raise
        except Exception as e:  # noqa: BLE001 - add the block context
            raise self._wrap(e, t) from e
        self.X, self.Y = X, Y
        self.k = k + 1
        self._check(t1)
        if self._side:
            self._side_effects()

    def _span_end(self, k):
        """Last step index up to which one adaptive solve may run from step k:
        the next periodic sample hit (or the horizon)."""
        if not self._span or self.horizon is None:
            return k + 1
        end = self.horizon
        eng = self.eng
        for i, p in enumerate(eng.periodic):
            if p:
                off, per = eng.off_k[i], eng.per_k[i]
                nxt = off if k < off else off + ((k - off) // per + 1) * per
                end = min(end, nxt)
        return max(end, k + 1)

    def value(self, ref):
        """Current value of an output port (handle or ``"block.port"``)."""
        i, o = self.compiled.resolve(ref)
        return self.Y[i][o]

    def state(self, block, name):
        """Current value of a state of a block (by path)."""
        return self.X[self.compiled.index(block)][name]

    def close(self):
        for i in self._side:
            self.compiled.blocks[i].on_stop()


def _blame(exc, compiled):
    """Name of the block whose method raised ``exc`` (from the traceback)."""
    tb = exc.__traceback__
    found = None
    ids = {id(b): n for n, b in zip(compiled.names, compiled.blocks)}
    while tb is not None:
        slf = tb.tb_frame.f_locals.get("self")
        if slf is not None and id(slf) in ids:
            found = ids[id(slf)]
        tb = tb.tb_next
    return found


def default_log(compiled):
    """Outputs logged when the user names none: every ``pose``/``position``
    output, else every output of the diagram."""
    refs = [f"{n}.{o}" for n, b in zip(compiled.names, compiled.blocks)
            for o in b._outputs if o in ("pose", "position")]
    if not refs:
        refs = [f"{n}.{o}" for n, b in zip(compiled.names, compiled.blocks)
                for o in b._outputs]
    return refs


def _progress_wanted(progress):
    if progress is not None:
        return bool(progress)
    return sys.stderr.isatty() and not os.environ.get("CI")


def simulate(diagram, t_final, dt=0.01, solver="rk4", *, log=None, log_every=1,
             seed=0, t0=0.0, realtime=None, progress=None, check_finite=True,
             max_log_bytes=2 * 1024**3, params=None, x0=None, live=False):
    """Simulate ``diagram`` from ``t0`` to ``t_final`` and return :class:`Results`.

    Parameters
    ----------
    diagram : Diagram
    t_final : float
        End time (a whole number of steps is run: ``round((t_final-t0)/dt)``).
    dt : float
        Major step. Discrete periods must be multiples of it.
    solver : str or Solver
        ``"rk4"`` (default), ``"euler"``, ``"RK45"``, ``"DOP853"``, ``"LSODA"``
        or a :class:`~avblocks.core.solvers.Solver`.
    log : list of port handles or ``"block.port"`` strings, optional
        What to record. Default: every ``pose``/``position`` output (else all).
    log_every : int
        Record every ``log_every``-th major step (decimation).
    seed : int
        Seed for every random block.
    realtime : float, optional
        Pace the run to the wall clock: 1.0 is real time, 2.0 twice as fast.
        Late steps are counted as overruns; the run keeps going.
    progress : bool, optional
        Progress bar (default: only when stderr is a terminal and not in CI).
    check_finite : bool
        Stop at the first NaN/inf, naming the block and port.
    max_log_bytes : int
        Refuse a run whose log would exceed this much memory.
    params : dict, optional
        Numeric parameter values for this run, ``{"block.name": value}``
        (validated; the blocks' own values are restored afterwards).
    x0 : dict, optional
        Initial state values, ``{"block.state": value}``.
    live : bool or dict
        Run in the browser (extra ``[live]``): serve a page on 127.0.0.1
        (URL printed, with a token) that draws and steers the run; a dict
        passes options to :class:`avblocks.viz.live.LiveView`. Paced to real
        time unless ``realtime`` says otherwise.

    Returns
    -------
    Results
        Logged signals; on failure the :class:`SimulationError` carries the
        results logged so far in ``err.results``.
    """
    if live:  # --- live view hook (avblocks.viz.live owns the loop) ---
        from ..viz.live import simulate_live
        return simulate_live(diagram, t_final, dt, solver, live=live, log=log,
                             log_every=log_every, seed=seed, t0=t0, realtime=realtime,
                             check_finite=check_finite, max_log_bytes=max_log_bytes,
                             params=params, x0=x0)
    sim = Simulator(diagram, dt, solver, seed=seed, t0=t0, check_finite=check_finite,
                    x0=x0)
    binding = _param_binding(sim.compiled, params)
    with binding:
        return _run(sim, t_final, log, log_every, realtime, progress, max_log_bytes,
                    params)


def _param_binding(compiled, params):
    """A :class:`bound_parameters` for ``{"block.name": value}`` (validated)."""
    from .params import bound_parameters
    if params is None:
        return bound_parameters([])
    if not isinstance(params, dict):
        raise ParameterError("params must be a dict {'block.name': value}",
                             param="params", found=type(params).__name__)
    per_block = {}
    for path, v in params.items():
        i, name = compiled.param_index(path)
        blk = compiled.blocks[i]
        per_block.setdefault(i, (blk, {}))[1][name] = \
            blk._params[name].validate(v, compiled.names[i])
    return bound_parameters(list(per_block.values()))


def _run(sim, t_final, log, log_every, realtime, progress, max_log_bytes, params):
    try:
        span = float(t_final) - sim.t0
    except (TypeError, ValueError):
        span = float("nan")
    if not (math.isfinite(span) and span >= 0):
        raise ParameterError("t_final must be a number >= t0", param="t_final",
                             expected=f">= {sim.t0}", found=t_final)
    nsteps = int(round(span / sim.dt))
    log_every = int(log_every)
    if log_every < 1:
        raise ParameterError("log_every must be >= 1", param="log_every",
                             expected=">= 1", found=log_every)
    if realtime is not None and not (float(realtime) > 0):
        raise ParameterError("realtime factor must be > 0", param="realtime",
                             expected="> 0", found=realtime)
    if log is None:
        refs = default_log(sim.compiled)
    elif isinstance(log, (str, PortRef)):
        refs = [log]
    else:
        refs = list(log)
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
        raise ParameterError(
            f"the log would take {need / 1e9:.2f} GB", param="log",
            expected=f"<= {max_log_bytes / 1e9:.2f} GB",
            found=f"{len(specs)} signals x {nlog} samples",
            hint="log fewer signals or decimate with log_every")
    bufs = [np.empty((nlog, *p.shape), dtype=p.dtype) for p in specs]
    tlog = np.empty(nlog)
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
        try:
            from tqdm import tqdm
            bar = tqdm(total=nsteps, unit="step", leave=False)
        except ImportError:  # pragma: no cover - tqdm is a core dependency
            bar = None
    pace = None if realtime is None else float(realtime)
    overruns, worst = 0, 0.0
    wall0 = _time.perf_counter()
    sim.horizon = nsteps
    try:
        sim.init()
        record()
        tick = max(1, nsteps // 100)
        for k in range(nsteps):
            sim.step()
            if (k + 1) % log_every == 0:
                record()
            if pace is not None:
                target = wall0 + (k + 1) * sim.dt / pace
                now = _time.perf_counter()
                if now < target:
                    _time.sleep(target - now)
                else:
                    late = now - target
                    worst = max(worst, late)
                    if late > sim.dt / pace:
                        overruns += 1
            if bar is not None and (k + 1) % tick == 0:
                bar.update(tick)
    except SimulationError as e:
        meta["wall_time"] = _time.perf_counter() - wall0
        meta["error"] = str(e)
        e.results = partial()
        raise
    except KeyboardInterrupt:
        meta["interrupted_at"] = sim.t
        meta["wall_time"] = _time.perf_counter() - wall0
        res = partial()
        res.meta["interrupted"] = True
        return res
    finally:
        if bar is not None:
            bar.close()
        sim.close()
    wall = _time.perf_counter() - wall0
    meta["wall_time"] = wall
    meta["realtime_factor"] = (nsteps * sim.dt / wall) if wall > 0 else math.inf
    if pace is not None:
        meta["overruns"] = overruns
        meta["max_lateness"] = worst
    if hasattr(sim.solver, "nfev"):
        meta["nfev"] = sim.solver.nfev
    if count < nlog:
        return partial()
    return Results(tlog, dict(zip(names, bufs)), dict(zip(names, specs)), meta,
                   aliases)
