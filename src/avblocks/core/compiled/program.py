"""One compiled program per diagram structure: the traced run and its variants.

A :class:`Program` owns the pure function ``run(theta, X0) -> (logs, X_T)``
of the numeric parameters ``theta`` (``{"block.name": array}``) and the
initial states ``X0`` (one dict per block, random keys included). It is
written once per structure and lowered/compiled ahead of time for each way
it is used (a single run, a chunk of a vmapped ensemble, a gradient), so a
call with new values never traces or compiles again. Programs live in a
small module-level LRU cache keyed by :func:`structure.diagram_key` plus
the run settings (see :func:`cache_info`).

The run is a nested ``lax.scan``: the outer scan has one iteration per log
sample, which computes and records the logged outputs and then advances
``log_every`` major steps with the inner scan (skipped by a ``lax.cond``
after the last sample; logging every step, the sample and its step are one
branch of that cond, which computes the outputs once); the steps left over
when ``log_every`` does not divide the step count run after it. Only the
decimated log leaves the program: one copy. Each inner step computes its
outputs first and then integrates (see ``Program.run``), so the outputs and
the derivatives of one state are traced in one loop body and what blocks
share through :mod:`avblocks.core.memo` is computed once. The inner scan
carries the states (and the held outputs of periodic blocks) packed into one
buffer where the step is short elementwise work (:mod:`.carry`): XLA then
runs a step as one fused loop instead of one per state.

On CPU the programs are compiled with XLA's classic loop emitters
(:func:`compiler_options`): measured on W1 they run the step 1.5-2.5x
faster than the newer fusion emitters.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from contextlib import contextmanager
from types import SimpleNamespace

import numpy as np

from .. import diagnostics as _diagnostics
from .. import memo as _memo
from ..params import bound_parameters
from . import _jax
from . import persist as _persist
from .carry import scan_steps
from .engine import TracedEngine

_CACHE: OrderedDict = OrderedDict()
_CACHE_SIZE = 32
_LOCK = threading.Lock()
_STATS = {"traces": 0, "hits": 0, "misses": 0}
_TRACE_LOCK = threading.RLock()


def cache_info() -> dict:
    """Counters of the compile cache: ``traces`` (Python traces of a run =
    compilations), ``hits``/``misses`` of the structure cache, ``size``;
    ``xla_compiled`` / ``xla_from_disk`` (programs XLA built, or read
    from the persistent cache) and ``xla_seconds``."""
    return {**_STATS, "size": len(_CACHE), **{f"xla_{k}": v for k, v in COMPILES.items()}}


def clear_cache():
    """Forget every compiled program (the counters are kept)."""
    with _LOCK:
        _CACHE.clear()


def cache_dir():
    """The user's cache folder of avblocks: ``$AVBLOCKS_CACHE_DIR``, else the
    platform's user cache folder (:func:`avblocks.core.compiled.persist.cache_dir`).
    Compiled programs go in ``jax/``, grown neighbour-search plans in ``plans/``."""
    return _persist.cache_dir()


def cache_disabled() -> bool:
    """True when ``$AVBLOCKS_CACHE`` says off (``0``, ``off``, ``no``, ``false``)."""
    return _persist.cache_disabled()


def enable_persistent_cache(path=None, *, min_compile_time_s=0.0):
    """Keep compiled programs and grown plans under ``path`` (default
    :func:`cache_dir`) for every runner of this process, whatever their
    ``cache=`` says: JAX's persistent compilation cache in ``path/jax``
    (this sets JAX's global configuration, also over a folder you set
    yourself) and the plan store in ``path/plans`` (see
    :func:`avblocks.core.compiled.plans.use_plan_store`). Compiled runs do
    this by default in :func:`cache_dir` (see
    :mod:`avblocks.core.compiled.persist`); this is for another folder, or
    for JAX programs of your own. Returns the folder."""
    from pathlib import Path

    from . import plans as _plans
    jax = _jax.jax()
    root = Path(path) if path is not None else cache_dir()
    p = root / "jax"
    p.mkdir(mode=0o700, parents=True, exist_ok=True)
    _persist.set_jax_folder(p)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_time_s))
    _plans.use_plan_store(root / "plans")
    _listen()
    return root


def clear_persistent_cache(path=None):
    """Delete the compiled programs and stored plans under ``path``
    (default :func:`cache_dir`); returns the bytes freed. (Programs already
    loaded in this process stay; :func:`clear_cache` forgets those.)"""
    import shutil
    from pathlib import Path
    root = Path(path) if path is not None else cache_dir()
    freed = 0
    for sub in ("jax", "plans"):
        d = root / sub
        if d.is_dir():
            freed += sum(f.stat().st_size for f in d.rglob("*") if f.is_file())
            shutil.rmtree(d)
    from . import plans as _plans
    _plans.forget_plans()
    _persist.forget()
    return freed


#: XLA compilations of this process: ``compiled`` (built by XLA) and
#: ``from_disk`` (read from JAX's persistent cache), with XLA's seconds
COMPILES = {"compiled": 0, "from_disk": 0, "seconds": 0.0}
_EVENTS = {"hits": 0}
_LISTENING = [False]


def _listen():
    """Count JAX's persistent-cache hits (its monitoring events)."""
    if _LISTENING[0]:
        return
    _LISTENING[0] = True
    import jax.monitoring as mon

    def on_event(event, **_kw):
        if event == "/jax/compilation_cache/cache_hits":
            _EVENTS["hits"] += 1
    mon.register_event_listener(on_event)


def compiler_options() -> dict:
    """XLA options for avblocks programs (this module's own compiles only;
    nothing global). On CPU the classic loop emitters: XLA's newer fusion
    emitters recompute a fused producer for every column of an (N, k)
    result, which on the W1 benchmark made a step 1.5-2.5x slower
    (benchmarks/scaling.py --backend jax; docs/compiled.md)."""
    if _jax.jax().default_backend() == "cpu" and _OPTIONS_OK["cpu"]:
        return {"xla_cpu_use_fusion_emitters": False}
    return {}


# Whether this jaxlib's CPU compiler still knows the options above (newer
# XLA releases dropped the flag with the classic emitters: JAX 0.11 answers
# "No such compile option"). Learnt at the first compile of the process.
_OPTIONS_OK = {"cpu": True}


def compile_lowered(lowered, cache=True):
    """``lowered.compile(compiler_options())``, falling back to XLA's own
    defaults (once per process) where this jaxlib rejects an option;
    counted in :data:`COMPILES` (built, or read from the persistent cache).
    ``cache``: a runner's cache folder, or None: compiled with JAX's
    persistent cache off (:func:`avblocks.core.compiled.persist.programs`)."""
    import time
    _listen()
    hits, t = _EVENTS["hits"], time.perf_counter()
    with _persist.programs(cache):
        exe = _compile_lowered(lowered)
    if _EVENTS["hits"] > hits:
        COMPILES["from_disk"] += 1
    else:
        COMPILES["compiled"] += 1
    COMPILES["seconds"] += time.perf_counter() - t
    return exe


def _compile_lowered(lowered):
    opts = compiler_options()
    if not opts:
        return lowered.compile()
    try:
        return lowered.compile(opts)
    except Exception as e:      # jax.errors.JaxRuntimeError: INVALID_ARGUMENT
        if "No such compile option" not in str(e):
            raise
        _OPTIONS_OK["cpu"] = False
        return lowered.compile()


def get_program(key, factory):
    """The cached program for ``key``, or a new one from ``factory()``."""
    with _LOCK:
        prog = _CACHE.get(key)
        if prog is not None:
            _CACHE.move_to_end(key)
            _STATS["hits"] += 1
            return prog
        _STATS["misses"] += 1
    prog = factory()
    with _LOCK:
        _CACHE[key] = prog
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    return prog


def signature(tree):
    """Hashable (structure, shapes, dtypes) of a pytree of arrays."""
    jax = _jax.jax()
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    return (treedef, tuple((np.shape(x), np.dtype(x.dtype).str) for x in leaves))


class Program:
    """The traced run of one diagram structure with fixed settings."""

    def __init__(self, compiled, *, dt, t0, nsteps, log_every, log_idx, solver, x64):
        jax = _jax.jax()
        self.cd = compiled
        self.dt, self.t0 = float(dt), float(t0)
        self.nsteps, self.log_every = int(nsteps), int(log_every)
        self.nlog = self.nsteps // self.log_every + 1
        self.log_idx = list(log_idx)
        self.solver = solver
        self.x64 = bool(x64)
        with _jax.x64(self.x64):
            canon = jax.dtypes.canonicalize_dtype
            self.eng = TracedEngine(compiled, dt, jax.numpy, canon)
        self.slots = [(f"{n}.{k}", i, k) for i, (n, b) in
                      enumerate(zip(compiled.names, compiled.blocks)) for k in b._params]
        from .structure import diagram_key
        self.struct = diagram_key(compiled)
        #: the rows of the needs tally the run returns (core.diagnostics)
        self.need_rows = _diagnostics.rows_of(compiled.blocks, compiled.names)
        self.traces = 0
        #: the uses ("run", "ensemble") whose split XLA partitioned with
        #: communication between devices: runners compile them for one device
        self.one_device = set()
        self._step_bytes = None
        self._exe = {}
        self._lock = threading.Lock()

    # ------------------------------------------------------------ the run
    def run(self, theta, X0, remat=False):
        """Pure: ``(logs, X_T, needs)`` for parameters ``theta`` and states
        ``X0``; ``needs`` is the tally of what the neighbour searches needed
        (rows :attr:`need_rows`, see :mod:`avblocks.core.diagnostics`).
        Must be called under a JAX transformation (it traces)."""
        jax = _jax.jax()
        jnp, lax = jax.numpy, jax.lax
        self._count_trace()
        with self._body(theta, remat) as body:
            carry, logs = lax.scan(body.outer, body.init(X0), jnp.arange(self.nlog))
            carry = body.finish(carry)
        return logs, carry[0], body.needs(carry)

    def segment(self, theta, carry, i0, length):
        """Pure: one segment of the run, ``(carry, rows)``: the outer
        iterations (log samples) ``i0 .. i0 + length - 1`` of :meth:`run`,
        traced from the same body, so a run made of segments computes what
        :meth:`run` computes, value for value (tested bit for bit).

        ``carry`` is ``(X, held outputs, needs)``; with ``i0 == 0`` its
        outputs and needs are placeholders (:meth:`segment_start`) and the
        segment first computes the initial outputs from ``X``, as
        :meth:`run` does. ``i0`` is traced: one compiled segment serves
        every position. Iterations past the last sample (the last segment
        padded to ``length``) repeat the last sample's outputs without
        advancing (their rows are dropped); the steps left over when
        ``log_every`` does not divide the step count run at the end of the
        segment that reaches the last sample. Must be called under a JAX
        transformation (it traces)."""
        jax = _jax.jax()
        jnp, lax = jax.numpy, jax.lax
        self._count_trace()
        nlog = self.nlog
        with self._body(theta, False) as body:
            carry = lax.cond(i0 == 0, lambda c: body.init(c[0]), lambda c: c, carry)
            idx = jnp.minimum(i0 + jnp.arange(length), nlog - 1)
            carry, rows = lax.scan(body.outer, carry, idx)
            carry = lax.cond(i0 + length >= nlog, body.finish, lambda c: c, carry)
        return carry, rows

    def segment_start(self, X0):
        """The carry a first :meth:`segment` takes: the initial states and
        zeros in place of the held outputs and needs (of the declared
        shapes and this program's dtypes); ``segment(i0=0)`` replaces them."""
        jax = _jax.jax()
        canon = jax.dtypes.canonicalize_dtype
        with _jax.x64(self.x64):
            fdt = np.dtype(canon(np.float64))
        needs = np.zeros((len(self.need_rows), 4), fdt) if self.need_rows else None
        return (X0, self._zero_held(), needs)

    def _zero_held(self):
        """Zeros in place of the periodic blocks' held outputs (declared
        shapes, this program's dtypes; ``{}`` for the other blocks)."""
        canon = _jax.jax().dtypes.canonicalize_dtype
        with _jax.x64(self.x64):
            return [{o: np.zeros(p.shape, canon(p.dtype)) for o, p in b._outputs.items()}
                    if per else {} for b, per in zip(self.cd.blocks, self.eng.periodic)]

    def _count_trace(self):
        self.traces += 1
        _STATS["traces"] += 1

    @contextmanager
    def _body(self, theta, remat):
        """The pieces of the traced run (inside the parameter binding and
        memo they need): ``init(X0) -> carry``, ``outer(carry, i) -> (carry,
        logged row)``, ``finish(carry)`` (the steps left after the last
        sample) and ``needs(carry)``."""
        jax = _jax.jax()
        jnp, lax = jax.numpy, jax.lax
        per_block = {}
        for path, i, k in self.slots:
            per_block.setdefault(i, (self.cd.blocks[i], {}))[1][k] = theta[path]
        eng, dt, t0 = self.eng, self.dt, self.t0
        le, nlog, idx = self.log_every, self.nlog, self.log_idx
        rows = self.need_rows
        tally = _diagnostics.tally
        with bound_parameters(list(per_block.values())), _memo.active(_memo.Memo()):
            fdt = jnp.asarray(0.0).dtype

            # The carry is (X_k, Y_k-1, needs): each step first computes its
            # outputs at t_k (periodic blocks hold Y_k-1 between hits), then
            # the updates and the solver step. Outputs and derivatives of one
            # state are so traced in one body, where values blocks share
            # through core.memo (the heading trig of a unicycle and its
            # controller) become one operation.
            # Only the outputs of periodic blocks are read from the carry (held
            # between hits): the others are not carried.
            def held(Y):
                return [y if p else {} for y, p in zip(Y, eng.periodic)]

            # The first sample (and step) computes the outputs at t0 again,
            # and every periodic block without an offset hits there: then the
            # held outputs and the needs tally start as zeros (overwritten at
            # k = 0, the same values) and the program holds one copy fewer
            # of the diagram's outputs (its searches included) to compile.
            # A block with an offset holds its initial output until its first
            # hit: only then are the outputs at t0 computed here.
            first_hit_all = all(h is not False for h in eng.hits(0))

            def init(X0):
                zeros = jnp.zeros((len(rows), 4), fdt)
                if first_hit_all:
                    return (X0, self._zero_held(), zeros if rows else None)
                with tally(rows, zeros) as tl:
                    Y0 = eng.all_outputs(t0, X0, [dict() for _ in self.cd.blocks])
                return (X0, held(Y0), tl.value if rows else None)

            def stepped(carry, k):
                """Step k: its outputs (also returned), updates, solver step."""
                X, Yp, N = carry
                t = t0 + k * dt
                hit = eng.hits(k)
                with tally(rows, N) as tl:
                    Y = eng.major_outputs(t, X, Yp, hit)
                    X = eng.update(t, X, Y, hit)
                    X = self._integrate(t, X, Y)
                return (X, held(Y), tl.value if rows else None), Y

            def step(carry, k):
                return stepped(carry, k)[0]

            # The step loop carries its state packed where the step is
            # elementwise (see .carry): one fused loop per step, not several.
            def advance(carry, k0, count):
                return scan_steps(step, carry, k0 + jnp.arange(count), fdt)

            def advance_le(carry, k0):
                return advance(carry, k0, le)

            if remat:
                advance_le = jax.checkpoint(advance_le)

            def logged(Y):
                return [Y[j][o] for j, o in idx]

            # What a sample's searches needed counts only where a logged
            # value can read a search at that sample (the final sample: a
            # sample followed by its step repeats every search there, with
            # the same needs): else the tally alone kept the searches' sort
            # and slot ranges alive at every sample (two of each in a call
            # logged at its ends).
            reads = self._logged_reads_search()

            def sample(carry, k, final):
                """The outputs at sample k, logged, without a step;
                ``final``: a bool, or a traced one (segments)."""
                with tally(rows, carry[2]) as tl:
                    Y = eng.major_outputs(t0 + k * dt, carry[0], carry[1], eng.hits(k))
                N = carry[2]
                if rows and reads and final is not False:
                    N = tl.value if final is True else jnp.where(final, tl.value, N)
                return (carry[0], carry[1], N), logged(Y)

            # Logging every step, a sample and its step are one branch of the
            # cond: the outputs are computed once, logged and integrated with
            # (computing them for the sample and again in the step cost a
            # second neighbour search per step), and fuse with the step as in
            # the loop; the sample after the last step only computes them.
            # With log_every > 1 (or checkpointed steps) the loop computes a
            # sample's outputs again: one evaluation more per sample.
            once = le == 1 and not remat

            def outer(carry, i):
                k = i * le
                if once:
                    def go(c):
                        c, Y = stepped(c, k)
                        return c, logged(Y)
                    return lax.cond(i < nlog - 1, go, lambda c: sample(c, k, True), carry)
                carry, row = sample(carry, k, i >= nlog - 1)
                carry = lax.cond(i < nlog - 1, lambda c: advance_le(c, k),
                                 lambda c: c, carry)
                return carry, row

            rem = self.nsteps - (nlog - 1) * le

            def finish(carry):
                return advance(carry, (nlog - 1) * le, rem) if rem else carry

            def needs(carry):
                return carry[2] if rows else jnp.zeros((0, 4), fdt)

            yield SimpleNamespace(init=init, outer=outer, finish=finish, needs=needs)

    def _logged_reads_search(self) -> bool:
        """Whether a logged signal can read, at its sample, a neighbour
        search made there: a block that owns a search is among the logged
        blocks or upstream of them through direct-feedthrough wires (a
        block without feedthrough gives its output from its state)."""
        if not self.need_rows:
            return False
        owners = {name for name, _ in self.need_rows}
        read = self.eng.feedthrough_ancestors(j for j, _ in self.log_idx)
        return any(self.cd.names[j] in owners for j in read)

    def needs(self, value):
        """``{(block name, search number): [capacity, hits, reach, span]}``
        from a run's (or an ensemble's, max over runs) needs tally."""
        v = np.asarray(value)
        if v.ndim == 3:
            v = v.max(axis=0)
        return {k: v[r] for k, r in self.need_rows.items()}

    def _integrate(self, t, X, Y):
        """The solver step from t to t + dt; a switch time of a source (a
        ``Step``) strictly inside it splits it, as the NumPy simulator does
        (``Simulator._advance``): the part before ends one ulp short of the
        switch, the outputs are recomputed at it, the rest follows. Switch
        times are traced parameters, so the split is a ``lax.cond`` taken
        only at the steps that contain one; the sub-steps of a step without
        a switch there have zero length (an exact no-op). Because the run
        integrates up to the switch exactly, gradients with respect to a
        switch time are those of the true solution."""
        eng, solver, dt = self.eng, self.solver, self.dt
        events = [b for b in self.cd.blocks if hasattr(b, "switch_times")]
        if not events:
            return solver.step(eng, t, X, Y, dt)
        jax = _jax.jax()
        jnp = jax.numpy
        t1 = t + dt
        tol = 1e-9 * dt
        tes = jnp.sort(jnp.stack([jnp.asarray(te, dtype=jnp.asarray(t).dtype).reshape(())
                                  for b in events for te in b.switch_times()]))
        inside = (tes > t + tol) & (tes < t1 - tol)

        def split(X):
            cur, Yc = t, Y
            for j in range(tes.shape[0]):
                # one ulp short of the switch; d(left)/d(te) = 1 for gradients
                # (JAX has no derivative of nextafter)
                te = tes[j]
                ts = jax.lax.stop_gradient(te)
                left = te + (jnp.nextafter(ts, -jnp.inf) - ts)
                h = jnp.where(inside[j], left - cur, 0.0)
                X = solver.step(eng, cur, X, Yc, h)
                Ys = eng.minor_outputs(tes[j], X, Yc)
                Yc = jax.tree_util.tree_map(lambda a, b, c=inside[j]: jnp.where(c, a, b),
                                            Ys, Yc)
                cur = jnp.where(inside[j], left, cur)
            return solver.step(eng, cur, X, Yc, t1 - cur)

        # the branches' searches report to the step's tally: carried in and out
        X, N = jax.lax.cond(jnp.any(inside), _diagnostics.through(split),
                            _diagnostics.through(lambda X: solver.step(eng, t, X, Y, dt)),
                            (X, _diagnostics.held()))
        _diagnostics.absorb(N)
        return X

    # ------------------------------------------------------- executables
    def executable(self, mode, build, args, compiled=None, cache=True):
        """Ahead-of-time compiled ``build()`` for ``args`` (cached by mode and
        argument signature): returns (callable, seconds spent compiling).

        ``compiled`` is the requesting runner's diagram (same structure when
        it was compiled). If the blocks this program was first traced with
        have since been changed structurally, it traces with those instead.
        ``cache``: the runner's cache folder (None: not read from or written
        to JAX's persistent cache; see :func:`compile_lowered`).
        Traces are serialized: binding traced parameter values to blocks
        must not race with another trace."""
        import time

        jax = _jax.jax()
        key = (mode, signature(args))
        with self._lock:
            exe = self._exe.get(key)
        if exe is not None:
            return exe, 0.0
        with _TRACE_LOCK:
            with self._lock:
                exe = self._exe.get(key)
            if exe is not None:
                return exe, 0.0
            self._current(compiled)
            t = time.perf_counter()
            with _jax.x64(self.x64):
                exe = compile_lowered(jax.jit(build()).lower(*args), cache)
            spent = time.perf_counter() - t
        with self._lock:
            self._exe[key] = exe
        return exe, spent

    def step_bytes(self, args, compiled=None) -> int:
        """Bytes of the largest array one step of one run computes
        (:func:`.chunking.largest_step_array` of the run traced for
        ``args = (theta, X0)``, one run's values); traced once per program
        and remembered. This probe is not a compilation: it leaves
        :attr:`traces` and :func:`cache_info` as they were."""
        if self._step_bytes is not None:
            return self._step_bytes
        from .chunking import largest_step_array
        jax = _jax.jax()
        with _TRACE_LOCK:
            self._current(compiled)
            counts = self.traces, _STATS["traces"]
            try:
                with _jax.x64(self.x64):
                    jp = jax.make_jaxpr(self.run)(*args)
            finally:
                self.traces, _STATS["traces"] = counts
        self._step_bytes = largest_step_array(jp)
        return self._step_bytes

    def _current(self, compiled):
        """Trace with ``compiled``'s blocks when the blocks this program was
        first traced with have since been changed structurally."""
        from .structure import diagram_key
        if compiled is not None and compiled is not self.cd and \
                diagram_key(self.cd) != self.struct:
            self._rebind(compiled)

    def _rebind(self, compiled):
        jax = _jax.jax()
        self.cd = compiled
        with _jax.x64(self.x64):
            self.eng = TracedEngine(compiled, self.dt, jax.numpy,
                                    jax.dtypes.canonicalize_dtype)
