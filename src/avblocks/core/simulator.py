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
import threading

import numpy as np

from . import codegen
from . import memo as _memo
from . import rng as _rng
from .diagram import CompiledDiagram, Diagram
from .engine import Engine
from .errors import AvError, ParameterError, ShapeError, SimulationError
from .runguard import (  # noqa: F401  (default_log, initial_values: importable here as before)
    _seed,
    default_log,
    finite_number,
    initial_values,
    log_every_that_fits,
    major_step,
)
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
        self.dt = major_step(dt)
        self.solver = make_solver(solver)
        self.seed = _seed(seed)
        self.t0 = finite_number(t0, "t0")
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
