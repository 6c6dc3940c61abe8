"""Running a diagram: :class:`Simulator` (step by hand) and :func:`simulate`.

The major step
--------------
With major step ``h`` and ``t_k = t0 + k h``, the simulator does::

    init:   on_start of side-effect blocks (an interface block connects and
               may set its initial state from the robots' first poses)
            X <- initial states (random keys seeded from seed and block path)
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

from . import codegen
from . import memo as _memo
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
        self.seed = _seed(seed)
        self.t0 = _finite(t0, "t0")
        if not isinstance(check_finite, (bool, np.bool_)):
            raise ParameterError("check_finite must be True or False",
                                 param="check_finite", found=repr(check_finite)[:40])
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
        # blocks whose outputs jump at known times (Step): a fixed-step
        # solver restarts there instead of straddling the jump
        self._event_blocks = ([b for b in diagram.blocks if hasattr(b, "switch_times")]
                              if self.solver.fixed_step else [])
        self._fcheck = self.check_finite and bool(self._fx_state or self._fx_dstate)
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
        self._fast = None       # generated major step (see codegen), set by init()
        self._memo = _memo.Memo()   # values blocks share within and across steps
        self.k = 0
        self.X = None
        self.Y = None
        self._Yprev = None

    #: Use the major step generated once per diagram (:mod:`.codegen`) for
    #: Euler and RK4; ``False`` runs the generic engine (same results).
    use_codegen = True

    # --------------------------------------------------------------- state
    @property
    def t(self) -> float:
        return self.t0 + self.k * self.dt

    def _check_x0(self, x0):
        return initial_values(self.compiled, x0)[0]

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
        self._Yprev = None
        self._memo.clear()
        # on_start first: an interface block (robots) connects there and may
        # set its initial state from what it receives (the robots' poses)
        for i in self._side:
            self.compiled.blocks[i].on_start()
        self.X = self.initial_states()
        Y0 = [dict() for _ in self.compiled.blocks]
        self.Y = self._guard(self.eng.all_outputs, self.t0, self.X, Y0)
        self._fast = None
        if self.use_codegen and codegen.supported(self.solver) and not self._event_blocks:
            self._fast = codegen.make_step(self.eng, self.solver)
        self._check_declared()
        self._check(self.t0)
        self.check_outputs(self.t0)
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
        except AvError as e:
            raise self._enrich(e, t) from e
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
        prev = getattr(self, "_Yprev", None)
        if state is not None and prev is not None:
            # a state went bad during the step: an input that drove the step
            # (a controller's output at t_k) is the first suspect
            for i, o in self._fx:
                if not np.all(np.isfinite(prev[i][o])):
                    raise SimulationError(
                        "output is NaN or infinite", block=self.compiled.names[i],
                        port=o, time=t - self.dt,
                        hint=f"it drove the step to t={t:.6g}, where "
                             f"'{self.compiled.names[state[0]]}.{state[1]}' became "
                             "non-finite")
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
        fast = self._fast
        token = _memo.activate(self._memo)
        try:
            if fast is not None:             # the generated step (codegen)
                X, Y = fast(self.X, self.Y, t, t1, k, h)
            else:
                if self._queue:              # inside a span: no discrete event
                    X = self._queue.pop()
                else:
                    X = eng.update(t, self.X, self.Y, eng.hits(k))
                    end = self._span_end(k)
                    states = None
                    if end > k + 1:
                        times = [self.t0 + j * h for j in range(k + 1, end + 1)]
                        states = self._try_span(t, X, times)
                    if states is not None:
                        self._queue = states[::-1]
                        X = self._queue.pop()
                    else:
                        X = self._advance(t, X, h)
                Y = eng.major_outputs(t1, X, self.Y, eng.hits(k + 1))
        except AvError as e:
            raise self._enrich(e, t) from e
        except Exception as e:  # noqa: BLE001 - add the block context
            raise self._wrap(e, t) from e
        finally:
            _memo.deactivate(token)
        self._Yprev = self.Y        # the outputs that drove this step (for blame)
        self.X, self.Y = X, Y
        self.k = k + 1
        if fast is None or self._fcheck:
            self._check(t1)
        if self._side:
            self._side_effects()

    def _advance(self, t, X, h):
        """Integrate from ``t`` to ``t + h``; a source discontinuity strictly
        inside the step splits it: the part before ends one ulp short of the
        switch time (so every stage sees the value before the jump), the
        part after starts from outputs recomputed at the switch (the value
        after it). Fixed-step solvers then keep their order across jumps."""
        eng, Y = self.eng, self.Y
        if not self._event_blocks:
            return self.solver.step(eng, t, X, Y, h)
        t1 = t + h
        if self._event_blocks:
            tol = 1e-9 * h
            ev = sorted({float(te) for b in self._event_blocks
                         for te in b.switch_times() if t + tol < float(te) < t1 - tol})
            for te in ev:
                t_left = float(np.nextafter(te, -np.inf))
                X = self.solver.step(eng, t, X, Y, t_left - t)
                Y = eng.minor_outputs(te, X, Y)
                t = t_left
            if ev:
                return self.solver.step(eng, t, X, Y, t1 - t)
        return self.solver.step(eng, t, X, Y, h)

    def _try_span(self, t, X, times):
        """One adaptive solve across ``times``; when it fails, spans are
        switched off so the step-by-step rerun reports the fault at the
        major step where it happens (with every sample before it logged)."""
        try:
            return self.solver.integrate(self.eng, t, X, self.Y, times)
        except Exception:  # noqa: BLE001 - located by the step-by-step rerun
            self._span = False
            return None

    def _enrich(self, e, t):
        """A SimulationError raised without time or block gets both."""
        if isinstance(e, SimulationError) and e.time is None and e.results is None:
            name = _blame(e, self.compiled) or e.block
            err = type(e)(e.cause, block=name, port=e.port, time=t,
                          expected=e.expected, found=e.found, hint=e.hint)
            return err
        return e

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
        """Run every side-effect block's ``on_stop`` (all of them, whatever
        one raises) and return the failures as ``[(block name, exception)]``
        (an interrupt while a block stops counts as one). Never raises: a
        failing ``on_stop`` must not hide the results or the run's own error."""
        failures = []
        for i in self._side:
            try:
                self.compiled.blocks[i].on_stop()
            except BaseException as e:  # noqa: BLE001 - collected, reported by caller
                failures.append((self.compiled.names[i], e))
        return failures


def initial_values(compiled, x0, runs=None):
    """Checked initial values ``({(block index, state): array}, batched)``
    from ``{"block.state": value}``. With ``runs`` (an ensemble), a value of
    shape ``(runs, *shape)`` is one per run and its key is in ``batched``."""
    out, batched = {}, set()
    if x0 is None:
        return out, batched
    if not isinstance(x0, dict):
        raise ParameterError("x0 must be a dict {'block.state': value}", param="x0",
                             found=type(x0).__name__)
    for path, v in x0.items():
        bpath, _, nm = str(path).rpartition(".")
        i = compiled.index(bpath) if bpath else compiled.index(str(path))
        b = compiled.blocks[i]
        if nm not in b._init or nm in b._random:
            raise ParameterError("no such state", block=bpath, param=nm,
                                 expected=sorted(set(b._init) - b._random), found=nm)
        old = b._init[nm]
        try:
            a = np.array(v, dtype=old.dtype)
        except (TypeError, ValueError):
            raise ParameterError("initial value must be numeric", block=bpath,
                                 param=nm, found=repr(v)[:60]) from None
        if runs is not None and a.shape == (runs, *old.shape):
            batched.add((i, nm))
        elif a.shape != old.shape:
            raise ParameterError("initial value has the wrong shape", block=bpath,
                                 param=nm, expected=old.shape if runs is None else
                                 f"{old.shape} or {(runs, *old.shape)}", found=a.shape)
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise ParameterError("initial value must be finite", block=bpath, param=nm)
        out[(i, nm)] = a
    return out, batched


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


def simulate(diagram, t_final, dt=0.01, solver="rk4", *, log=None, log_every=None,
             seed=0, t0=0.0, realtime=None, progress=None, check_finite=True,
             max_log_bytes=2 * 1024**3, params=None, x0=None, backend="numpy",
             live=False, **backend_options):
    """Simulate ``diagram`` from ``t0`` to ``t_final`` and return :class:`Results`.

    Parameters
    ----------
    diagram : Diagram
    t_final : float
        End time. ``t_final - t0`` must be a whole number of major steps
        ``dt`` (to 1e-9 of a step): otherwise a :class:`ParameterError` names
        the two nearest valid end times (a run never stops short silently).
    dt : float
        Major step. Discrete periods must be multiples of it.
    solver : str or Solver
        ``"rk4"`` (default), ``"euler"``, ``"RK45"``, ``"DOP853"``, ``"LSODA"``
        or a :class:`~avblocks.core.solvers.Solver`.
    log : list of port handles or ``"block.port"`` strings, optional
        What to record. Default: every ``pose``/``position`` output (else all).
    log_every : int, optional
        Record every ``log_every``-th major step (decimation). Default:
        every step, unless the log would exceed ``max_log_bytes`` (e.g.
        30,000 agents for 30 s at dt = 0.01): then the smallest decimation
        that fits, with a warning and ``res.meta["log_every"]`` saying so.
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
    backend : ``"numpy"`` (default) or ``"jax"``
        ``"jax"`` compiles the whole run (:mod:`avblocks.core.compiled`):
        same arguments and Results (plus ``res.final_state``), fixed-step
        solvers and traceable blocks only, no ``realtime``; it takes the
        option ``dtype="float32"`` (default ``"float64"``). A second run of
        the same structure with other numeric values does not recompile.
    live : bool or dict
        Run in the browser (extra ``[live]``): serve a page on 127.0.0.1
        (URL printed, with a token) that draws and steers the run; a dict
        passes options to :class:`avblocks.viz.live.LiveView`. Paced to real
        time unless ``realtime`` says otherwise. NumPy backend only.

    Returns
    -------
    Results
        Logged signals; on failure the :class:`SimulationError` carries the
        results logged so far in ``err.results``.
    """
    if live:  # --- live view hook (avblocks.viz.live owns the loop) ---
        if backend != "numpy" or backend_options:
            raise ParameterError("live=True runs the NumPy backend step by step",
                                 param="backend", expected="'numpy'", found=backend)
        from ..viz.live import simulate_live
        return simulate_live(diagram, t_final, dt, solver, live=live, log=log,
                             log_every=log_every, seed=seed, t0=t0, realtime=realtime,
                             check_finite=check_finite, max_log_bytes=max_log_bytes,
                             params=params, x0=x0)
    if backend != "numpy":
        if backend != "jax":
            raise ParameterError("unknown backend", param="backend",
                                 expected="'numpy' or 'jax'", found=backend)
        from .compiled import simulate_compiled
        return simulate_compiled(diagram, t_final, dt, solver, log=log,
                                 log_every=1 if log_every is None else log_every,
                                 seed=seed, t0=t0, realtime=realtime,
                                 progress=progress, check_finite=check_finite,
                                 max_log_bytes=max_log_bytes, params=params, x0=x0,
                                 backend=backend, **backend_options)
    if backend_options:
        raise ParameterError("unknown keyword argument(s) for backend='numpy'",
                             param=", ".join(sorted(backend_options)))
    sim = Simulator(diagram, dt, solver, seed=seed, t0=t0, check_finite=check_finite,
                    x0=x0)
    binding = _param_binding(sim.compiled, params)
    with binding:
        res = _run(sim, t_final, log, log_every, realtime, progress, max_log_bytes,
                   params)
    if sim.X is not None:       # the state at the end (as backend="jax" returns it)
        res.final_state = {f"{n}.{k}": v for n, x in zip(sim.compiled.names, sim.X)
                           for k, v in x.items()}
    return res


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


#: Most major steps one run may take (beyond it: refused, not hung).
MAX_STEPS = 10**10


def _seed(seed):
    from .params import integer
    return integer(seed, None, "seed", lo=0, hi=2**64 - 1)


def _finite(v, name):
    ok = not isinstance(v, (bool, np.bool_, str, bytes))
    f = math.nan
    if ok:
        try:
            f = float(v)
        except (TypeError, ValueError, OverflowError):
            ok = False
    if not (ok and math.isfinite(f)):
        raise ParameterError("must be a finite number", param=name,
                             expected="a number", found=repr(v)[:60])
    return f


def whole_steps(t0, t_final, dt):
    """Number of major steps from ``t0`` to ``t_final``; a
    :class:`ParameterError` unless ``t_final - t0`` is a whole number of
    steps ``dt`` (within 1e-9 of a step): a run never stops silently short
    of, or past, the time asked for."""
    span = t_final - t0
    if span < 0:
        raise ParameterError("t_final must be >= t0", param="t_final",
                             expected=f">= {t0:g}", found=t_final)
    steps = span / dt
    if not steps <= MAX_STEPS:
        raise ParameterError(f"the run would take {steps:.3g} major steps",
                             param="dt", expected=f"<= {MAX_STEPS:.0e} steps",
                             found=f"(t_final - t0) / dt = {steps:.3g}",
                             hint="a larger dt or a shorter run")
    n = int(round(steps))
    if abs(steps - n) > 1e-9 * max(1.0, steps):
        lo, hi = math.floor(steps), math.ceil(steps)
        if steps < 1:
            what, expected = ("dt is longer than the whole run",
                              f"t_final = t0 + k*dt with k >= 1, e.g. {t0 + dt:.10g}")
        else:
            what = "t_final - t0 is not a whole number of major steps"
            expected = f"t0 + k*dt, e.g. {t0 + lo * dt:.10g} or {t0 + hi * dt:.10g}"
        raise ParameterError(
            what, param="t_final", expected=expected,
            found=f"t_final={t_final:g} with dt={dt:g} ({steps:.6g} steps)",
            hint="change t_final, or pick a dt that divides t_final - t0")
    return n


def _log_every_that_fits(per_sample, nsteps, max_log_bytes):
    """The smallest decimation whose log (``nsteps // k + 1`` samples of
    ``per_sample`` bytes) fits in ``max_log_bytes``, or None."""
    samples = int(max_log_bytes // max(int(per_sample), 1))
    if samples < 2:
        return None
    return max(1, math.ceil(nsteps / (samples - 1)))


def _run(sim, t_final, log, log_every, realtime, progress, max_log_bytes, params):
    from .params import integer
    t_final = _finite(t_final, "t_final")
    nsteps = whole_steps(sim.t0, t_final, sim.dt)
    auto_log = log_every is None       # default: every step, unless too big
    log_every = 1 if auto_log else integer(log_every, None, "log_every", lo=1)
    if realtime is not None and not (_finite(realtime, "realtime") > 0):
        raise ParameterError("realtime factor must be > 0", param="realtime",
                             expected="> 0", found=realtime)
    if progress is not None and not isinstance(progress, (bool, np.bool_)):
        raise ParameterError("progress must be None, True or False", param="progress",
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
        fit = _log_every_that_fits(need // nlog, nsteps, max_log_bytes)
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
        try:
            from tqdm import tqdm
            bar = tqdm(total=nsteps, unit="step", leave=False)
        except ImportError:  # pragma: no cover - tqdm is a core dependency
            bar = None
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
                if bar is not None and (k + 1) % tick == 0:
                    bar.update(tick)
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
