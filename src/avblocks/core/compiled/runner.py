"""The :class:`Runner`: a compiled program of one diagram structure, run
with new parameters, initial states and seeds, as ensembles, or
differentiated. :mod:`avblocks.core.compiled.build` makes runners
(:func:`~avblocks.core.compiled.build.compile`)."""

from __future__ import annotations

import math
import time

import numpy as np

from .. import diagnostics as _diagnostics
from .. import rng as _rng
from ..block import Block as _Block
from ..errors import ParameterError
from ..results import Results
from . import _jax
from . import chunking as _chunking
from . import devices as _devices
from . import outcome as _outcome
from . import plans as _plans
from . import segments as _segments
from .outcome import check_finite as _check_finite
from .program import Program, get_program
from .structure import diagram_key, fingerprint


def _solver_key(solver):
    return (type(solver).__module__, type(solver).__qualname__, fingerprint(vars(solver)))


class Runner:
    """A compiled run of one diagram: call it with new values, never recompiles.

    ``runner(params=None, x0=None, seed=None) -> Results``
        one run; ``params`` ``{"block.name": value}`` and ``x0``
        ``{"block.state": value}`` override the blocks' current values.
    ``runner.ensemble(seeds=None, params=None, x0=None) -> Results``
        many runs at once (``vmap``), with a leading run axis.
    ``runner.grad(cost, wrt, ...)`` / ``runner.value_and_grad(...)``
        reverse-mode gradients of a scalar cost of the run's results.

    Made by :func:`compile`; see there. ``runner.compilations`` counts the
    traces of its program (shared with every runner of the same structure).
    """

    def __init__(self, compiled, program, *, names, specs, aliases, seed, dtype,
                 check_finite, solver_name, devices=None, shard="auto"):
        self.compiled = compiled
        self.program = program
        self.names = names
        self.specs = specs
        self.aliases = aliases
        self.seed = int(seed)
        self.dtype = dtype
        self.check_finite = bool(check_finite)
        self.solver_name = solver_name
        self.t = program.t0 + (program.log_every * np.arange(program.nlog)) * program.dt
        self.devices = devices if devices is not None else _devices.resolve(None)
        self._run_exe = None            # (placement, executable) of __call__
        self._kept, self._kept_for = {}, None  # device copies of inputs (_inputs)
        self._keep_inputs = True
        self._fixed = None              # (program, the meta all its runs share)
        #: the cache folder of its programs and plans (None: memory only;
        #: see :mod:`avblocks.core.compiled.persist`), set by ``compile``
        self.cache = None
        self.plan_store = None
        n = _devices.agents_of(compiled)
        #: how a single run uses several devices: "auto" (its agents split
        #: when they never interact) or "agents" (split whatever they do;
        #: see :mod:`avblocks.core.compiled.devices`)
        self.shard = _devices.check_shard(shard, self.devices, n)
        self._single = _devices.Placement(
            self.devices, n if n and (n >= _devices.MIN_AGENTS_TO_SPLIT
                                      or self.shard == "agents") else None)

    @property
    def log_bytes(self) -> int:
        """Bytes of the log of one run."""
        p = self.program
        item = 8 if p.x64 else 4
        return sum(p.nlog * math.prod(s.shape) * (
            item if np.dtype(s.dtype).kind == "f" else np.dtype(s.dtype).itemsize)
            for s in self.specs)

    @property
    def compilations(self) -> int:
        return self.program.traces

    @property
    def plans(self) -> dict:
        """The plans of the neighbour searches it runs, ``{"block/j":
        CellList}`` (see :func:`avblocks.core.compiled.get_plans`)."""
        return _plans.get_plans(self.compiled)

    def __repr__(self):
        p = self.program
        return (f"Runner({len(self.compiled.blocks)} blocks, {p.nsteps} steps of "
                f"{p.dt:g} s, log every {p.log_every}: {self.names}, {self.dtype})")

    # ------------------------------------------------------------ values
    def _fdtype(self):
        return np.float64 if self.program.x64 else np.float32

    def _cast(self, a):
        a = np.asarray(a)
        if a.dtype.kind == "f":
            return a.astype(self._fdtype(), copy=False)
        if a.dtype == np.int64 and not self.program.x64:
            return a.astype(np.int32)
        return a

    def _theta(self, params, runs=None):
        """{path: array} of every numeric parameter (validated), and for an
        ensemble the set of paths given one value per run."""
        cd = self.compiled
        theta = {f"{n}.{k}": np.asarray(v) for n, b in zip(cd.names, cd.blocks)
                 for k, v in b.parameter_values().items()}
        batched = set()
        if params is None:
            params = {}
        if not isinstance(params, dict):
            raise ParameterError("params must be a dict {'block.name': value}",
                                 param="params", found=type(params).__name__)
        for path, v in params.items():
            i, name = cd.param_index(path)
            spec = cd.blocks[i]._params[name]
            key = f"{cd.names[i]}.{name}"
            if runs is not None and np.ndim(v) == len(spec.shape) + 1:
                v = np.asarray(v, dtype=float)
                if len(v) != runs:
                    raise ParameterError("one value per run expected", param=key,
                                         expected=f"leading axis {runs}", found=v.shape)
                theta[key] = np.stack([spec.validate(v[r], cd.names[i])
                                       for r in range(runs)])
                batched.add(key)
            else:
                theta[key] = spec.validate(v, cd.names[i])
        return {k: self._cast(v) for k, v in theta.items()}, batched

    def _theta_plain(self, cast=True):
        """{path: array} of every numeric parameter at the blocks' own values
        (validated when they were set), cast to the program's types (or as
        the blocks hold them: ``cast=False``)."""
        cd = self.compiled
        cast = self._cast if cast else (lambda a: a)
        return {f"{n}.{k}": cast(b.__dict__[k]) for n, b in zip(cd.names, cd.blocks)
                for k in b._params}

    def _x0_values(self, x0, runs=None):
        """{(block index, state): array} from ``{"block.state": value}``."""
        from ..runguard import initial_values
        return initial_values(self.compiled, x0, runs)

    def _states(self, x0vals, seeds, cast=True):
        """Initial states: declared values, ``x0`` overrides, random keys from
        each seed (exactly as the NumPy simulator seeds them); cast to the
        program's types unless ``cast=False``."""
        cd = self.compiled
        X = []
        for j, (name, b) in enumerate(zip(cd.names, cd.blocks)):
            # the declared arrays (a run never writes them), unless the
            # block says otherwise in its own initial_state()
            x = dict(b._init) if type(b).initial_state is _Block.initial_state \
                else b.initial_state()
            for (i, nm), v in x0vals.items():
                if i == j:
                    x[nm] = v
            for r in b._random:
                ks = [_rng.key(s, f"{name}.{r}") for s in seeds]
                x[r] = ks[0] if len(ks) == 1 else np.stack(ks)
            X.append({k: self._cast(v) for k, v in x.items()} if cast else x)
        return X

    def _inputs(self, place, theta, X0):
        """``(theta, X0)`` as the executable takes them: each array cast to
        the program's types and placed by ``place``.

        A frozen array (read-only and owning its data: a block's parameter
        value or declared initial state, :func:`avblocks.core.params.frozen`)
        cannot change while the block holds it -- a new value is a new
        array -- so its device copy is kept for the next call, and a call
        with unchanged values moves none of them to the device again
        (10^7 flocking agents, float64: 960 MB of parameters and initial
        states a call before; float32 also cast on the host each call).
        Only the copies the latest call used are kept (a block given a new
        value drops the old copy at the next call); ``keep_inputs = False``
        keeps none."""
        kept = self._kept if self._kept_for == place.key else {}
        now = {}

        def one(key, a):
            if not (self.keep_inputs and isinstance(a, np.ndarray)
                    and a.flags.owndata and not a.flags.writeable):
                return self._cast(a)
            hit = kept.get(key)
            if hit is None or hit[0] is not a:
                hit = (a, place.put(self._cast(a)))
            now[key] = hit
            return hit[1]
        th = {k: one(("theta", k), v) for k, v in theta.items()}
        xs = [{k: one(("x0", j, k), v) for k, v in x.items()} for j, x in enumerate(X0)]
        self._kept, self._kept_for = now, place.key
        return place((th, xs))

    @property
    def keep_inputs(self) -> bool:
        """Whether a call keeps the device copies of the unchanged inputs
        (parameter values, declared initial states) for the next call
        (default ``True``: see :meth:`_inputs`). They take device memory
        between calls, as much as the inputs of one run; ``False`` drops
        them now and places every input at each call."""
        return self._keep_inputs

    @keep_inputs.setter
    def keep_inputs(self, value):
        self._keep_inputs = bool(value)
        if not self._keep_inputs:
            self._kept = {}

    # --------------------------------------------------------------- run
    def _results(self, logs, XF, meta, runs=None, t=None, on_device=False):
        data = dict(zip(self.names, logs))
        res = Results(self.t if t is None else t, data, dict(zip(self.names, self.specs)), meta,
                      self.aliases, runs=runs)
        cd = self.compiled
        res.final_state = _outcome.final_states({f"{cd.names[i]}.{k}": v
                                                 for i, x in enumerate(XF)
                                                 for k, v in x.items()},
                                                on_device)
        return res

    def _meta(self, seed, params, wall, compile_s):
        p = self.program
        if self._fixed is None or self._fixed[0] is not p:
            # what every run of this program says the same (read once; the
            # seed's place kept for the key order)
            self._fixed = (p, {
                "backend": "jax", "device": _jax.jax().default_backend(),
                "dtype": self.dtype, "solver": self.solver_name, "dt": p.dt,
                "seed": None, "t0": p.t0, "t_final": p.t0 + p.nsteps * p.dt,
                "log_every": p.log_every, "steps": p.nsteps,
                "agents": max([s.n or 0 for s in self.specs] + [0]),
                "blocks": len(self.compiled.blocks)})
        meta = dict(self._fixed[1])
        meta.update(seed=seed, compile_time=compile_s, wall_time=wall, param_changes=[])
        meta["realtime_factor"] = (p.nsteps * p.dt / wall) if wall > 0 else math.inf
        if params:
            meta["params"] = {str(k): np.asarray(v, float).tolist()
                              for k, v in params.items()}
        return meta

    def _placed(self, key, build, place, args):
        """``(executable, compile seconds, placement, placed args)`` for
        ``args`` laid out by ``place``. A split program that XLA partitioned
        with communication between devices (agents that interact: a gather
        across agents, a neighbour sum) would wait on the other devices at
        every stage, so it is compiled for one device instead (waypoints,
        300 agents: 3.5 s split, 0.2 s on one device). Known without a
        compile: a single run whose blocks search neighbours (a search sorts
        every agent), and what an earlier compile of the structure learnt
        (kept with its plans, also across processes)."""
        prog = self.program
        spent = 0.0
        if place.split is not None and self.shard == "agents" and key[0] != "ensemble":
            return self._sharded(key, build, place, args)
        if place.split is not None and not self._one_device(key[0]):
            with _jax.x64(prog.x64):
                placed = place(args)
            exe, spent = prog.executable(key + (place.key,), build, placed, self.compiled,
                                         self.cache)
            if not _devices.communicates(exe):
                return exe, spent, place, placed
            prog.one_device.add(key[0])     # it communicates: known for every runner
            _plans.remember_one_device(self.compiled, key[0], self.plan_store)
        if place.split is not None:
            place = _devices.Placement(self.devices[:1])
        with _jax.x64(prog.x64):
            placed = place(args)
        exe, more = prog.executable(key + (place.key,), build, placed, self.compiled,
                                    self.cache)
        return exe, spent + more, place, placed

    def _sharded(self, key, build, place, args):
        """:meth:`_placed` of a run whose agents are split over the devices
        whatever they do (``shard="agents"``): traced under
        :func:`avblocks.core.diagnostics.sharded`, so each neighbour search
        answers each device's share of the queries there (see
        :mod:`avblocks.core.compiled.devices`); XLA adds the rest of the
        exchange (the gathers of neighbours' values)."""
        prog = self.program

        def sharded_build():
            fn = build()

            def run(*a):
                with _diagnostics.sharded(place.mesh, "d"):
                    return fn(*a)
            return run
        with _jax.x64(prog.x64):
            placed = place(args)
        exe, spent = prog.executable(key + (place.key, "agents"), sharded_build, placed,
                                     self.compiled, self.cache)
        return exe, spent, place, placed

    def _one_device(self, use):
        """Whether ``use`` ("run", "ensemble", ...) is known to communicate
        when split (see :meth:`_placed`)."""
        prog = self.program
        if use in prog.one_device:
            return True
        if use in ("run", "segment") and _plans.owned(self.compiled):
            return True
        if _plans.one_device(self.compiled, use, self.plan_store):
            prog.one_device.add(use)
            return True
        return False

    #: what a run does when a neighbour search overflows its plan
    #: (:mod:`avblocks.core.compiled.plans`): "replan" or "raise"
    on_overflow = "replan"

    def _rebuild_program(self):
        """Take the program of the diagram's current structure (after its
        searches were re-planned: see :mod:`avblocks.core.compiled.plans`)."""
        jax = _jax.jax()
        p, cd = self.program, self.compiled
        one = set(p.one_device)
        key = (diagram_key(cd), p.nsteps, p.log_every, tuple(self.names),
               _solver_key(p.solver), p.dt, p.t0, p.x64, str(jax.default_backend()))
        self.program = get_program(key, lambda: Program(
            cd, dt=p.dt, t0=p.t0, nsteps=p.nsteps, log_every=p.log_every,
            log_idx=p.log_idx, solver=p.solver, x64=p.x64))
        # a grown plan does not change whether the agents interact
        self.program.one_device |= one
        self.struct = key[0]
        self._run_exe = None

    def __call__(self, params=None, x0=None, seed=None, *, progress=None):
        """One run (see the class docstring). ``progress``: a callable
        ``progress(step, steps)`` or ``True`` (a bar) runs it in segments
        that report between them and can be stopped by a
        ``KeyboardInterrupt`` (the results so far come back, marked
        interrupted): see :mod:`avblocks.core.compiled.segments`. ``None``
        or ``False``: the whole run in one call."""
        jax = _jax.jax()
        seed = self.seed if seed is None else int(seed)
        report = _segments.reporter(progress)
        # no overrides (the common repeated call): the blocks' own values,
        # read afresh each call, without the validation an override needs
        known = self._run_exe if report is None else None
        # a repeated call (known program, one piece) casts and places its
        # inputs itself, keeping what did not change on the device
        theta = self._theta_plain(cast=known is None) if params is None \
            else self._theta(params)[0]
        X0 = self._states(self._x0_values(x0)[0] if x0 is not None else {}, [seed],
                          cast=known is None)
        prog = self.program
        if report is not None:
            res, needs, stopped = _segments.run(self, theta, X0, seed, params, report)
            over = _plans.overflows(self.compiled, prog.needs(_devices.host(needs))) \
                if prog.need_rows else ()
            if over and stopped:
                # not repeated (it was stopped), but its samples are suspect
                import warnings
                names = ", ".join(f"'{n}' ({m})" for n, _, _, m in over)
                res.meta["overflowed"] = [n for n, *_ in over]
                warnings.warn(f"the stopped compiled run's neighbour search overflowed its "
                              f"plan: {names}; its results may miss neighbours",
                              RuntimeWarning, stacklevel=2)
            elif over:
                return _plans.settle(self, over, lambda: self(params, x0, seed,
                                                              progress=progress))
            if self.check_finite:
                _check_finite(res)
            return res
        if known is not None:
            # validated values have the declared shapes and dtypes: the
            # signature is this runner's every time, no need to hash it again
            place, exe = known
            compile_s = 0.0
        else:
            exe, compile_s, place, args = self._placed(("run",), lambda: prog.run,
                                                       self._single, (theta, X0))
            self._single = place
            self._run_exe = (place, exe)
        with _jax.x64(prog.x64):
            if known is not None:
                args = self._inputs(place, theta, X0)
            t = time.perf_counter()
            logs, XF, needs = exe(*args)
            flat, tree = jax.tree_util.tree_flatten(XF)
            for a in logs:
                a.block_until_ready()
            for a in flat:
                a.block_until_ready()
            wall = time.perf_counter() - t
        large = _outcome.large(logs, flat)
        # a large run (10^7 agents: logs and final state of hundreds of MB)
        # is checked for NaN/inf on the device (a flag per array comes back,
        # not a scan of every value on the host), and its final state stays
        # there until it is read (res.final_state converts on access)
        finite = _outcome.finite_on_device(list(logs) + flat) \
            if (large and self.check_finite) else None
        logs = [_devices.host(a) for a in logs]
        XF = jax.tree_util.tree_unflatten(tree, flat if large else
                                          [_devices.host(a) for a in flat])
        res = self._results(logs, XF, self._meta(seed, params, wall, compile_s),
                            on_device=large)
        over = _plans.overflows(self.compiled, prog.needs(_devices.host(needs))) \
            if prog.need_rows else ()
        if over:
            return _plans.settle(self, over, lambda: self(params, x0, seed))
        if self.check_finite:
            _check_finite(res, finite)
        return res

    # ---------------------------------------------------------- ensemble
    def ensemble(self, seeds=None, params=None, x0=None, *, runs=None,
                 max_log_bytes=512 * 1024**2, chunk=None):
        """Many runs in one vmapped program; Results with a leading run axis.

        Parameters
        ----------
        seeds : sequence of int, optional
            One seed per run (random blocks draw independent streams).
        params : dict, optional
            ``{"block.name": value}``; a value with one more axis than the
            parameter (leading axis = runs) gives each run its own value,
            any other value is shared by all runs.
        x0 : dict, optional
            ``{"block.state": value}``; shape ``(runs, *state shape)`` per
            run, or the state's own shape for all runs.
        runs : int, optional
            Number of runs when neither ``seeds`` nor a per-run value says.
        max_log_bytes : int
            Largest log one vmapped call may produce: the runs are split into
            chunks of equal size under it (one compile for all chunks), each
            copied into the result arrays as it finishes.
        chunk : int, optional
            Runs per vmapped call, overriding the policy below (a multiple
            of the device count is split across the devices).

        Returns
        -------
        Results
            ``res[port]`` has shape ``(runs, T, ...)``; ``res.final_state``
            values ``(runs, ...)``; ``res.to_xarray()`` has a ``run`` dim.

        Notes
        -----
        Chunks: under ``max_log_bytes``; on a CPU also small enough that a
        step's arrays stay in the cache (each device gets ``CPU_STEP_BYTES
        // b`` runs, ``b`` the largest array one step of one run computes,
        found by tracing the run once, when it is at least
        ``CPU_MIN_ARRAY``; at least one run per device); on other platforms
        (GPU) as big as the log budget allows; then made equal. The
        chunking never changes the results beyond round-off. See
        :mod:`avblocks.core.compiled.chunking`.
        """
        jax = _jax.jax()
        R = _count_runs(seeds, params, x0, runs)
        seeds = [self.seed] * R if seeds is None else [int(s) for s in seeds]
        if len(seeds) != R:
            raise ParameterError("seeds and per-run values disagree on the number of "
                                 "runs", param="seeds", expected=R, found=len(seeds))
        theta, tb = self._theta(params, runs=R)
        x0vals, xb = self._x0_values(x0, runs=R)
        varied_seeds = len(set(seeds)) > 1
        X0 = self._states(x0vals, seeds if varied_seeds else seeds[:1])
        cd = self.compiled
        x_axes = [{k: (0 if ((i, k) in xb or (k in b._random and varied_seeds)) else None)
                   for k in X0[i]} for i, b in enumerate(cd.blocks)]
        t_axes = {k: (0 if k in tb else None) for k in theta}
        # chunking (see core.compiled.chunking)
        prog = self.program

        def step_bytes():                   # traced with the values of run 0
            one = ({k: (v if t_axes[k] is None else v[0]) for k, v in theta.items()},
                   [{k: (v if x_axes[i][k] is None else v[0]) for k, v in x.items()}
                    for i, x in enumerate(X0)])
            return prog.step_bytes(one, self.compiled)
        asked = chunk
        chunk = _chunking.chunk_size(R, self.log_bytes, max_log_bytes, self.devices,
                                     step_bytes, asked)
        place = _devices.Placement(self.devices, chunk)
        nchunks = -(-R // chunk)
        out = [np.empty((R, prog.nlog, *s.shape), dtype=_canon_np(s.dtype, prog.x64))
               for s in self.specs]
        finals = None

        def take(a, ax, lo, hi):
            if ax is None:
                return a
            part = a[lo:hi]
            if len(part) < chunk:        # pad the last chunk: same compiled size
                part = np.concatenate([part, np.repeat(part[-1:], chunk - len(part), 0)])
            return part

        def build():
            batched = jax.vmap(prog.run, in_axes=(t_axes, x_axes), axis_size=chunk)

            def run(theta, X0):
                with _diagnostics.vmapped():     # no branch on a batched value
                    return batched(theta, X0)
            return run

        exe, compile_s, wall, needs = None, 0.0, 0.0, None
        for c in range(nchunks):
            lo, hi = c * chunk, min(R, (c + 1) * chunk)
            th = {k: take(v, t_axes[k], lo, hi) for k, v in theta.items()}
            xs = [{k: take(v, x_axes[i][k], lo, hi) for k, v in x.items()}
                  for i, x in enumerate(X0)]
            if exe is None:
                key = ("ensemble", chunk, _axes_key(t_axes), _axes_key(x_axes))
                exe, compile_s, place, (th, xs) = self._placed(key, build, place,
                                                               (th, xs))
            else:
                with _jax.x64(prog.x64):
                    th, xs = place((th, xs))
            t = time.perf_counter()
            with _jax.x64(prog.x64):
                logs, XF, most = exe(th, xs)
                jax.block_until_ready((logs, XF))
            wall += time.perf_counter() - t
            most = _devices.host(most).max(axis=0)       # the largest over the runs
            needs = most if needs is None else np.maximum(needs, most)
            for o, a in zip(out, logs):
                o[lo:hi] = _devices.host(a)[:hi - lo]
            XF = jax.tree_util.tree_map(_devices.host, XF)
            if finals is None:
                finals = [{k: np.empty((R, *v.shape[1:]), v.dtype) for k, v in x.items()}
                          for x in XF]
            for f, x in zip(finals, XF):
                for k, v in x.items():
                    f[k][lo:hi] = v[:hi - lo]
        meta = self._meta(seeds[0], None, wall, compile_s)
        meta.update(runs=R, seeds=seeds, chunks=nchunks, chunk_size=chunk,
                    per_run_params=sorted(tb))
        meta["realtime_factor"] = (R * prog.nsteps * prog.dt / wall) if wall > 0 else math.inf
        res = self._results(out, finals, meta, runs=R)
        over = _plans.overflows(self.compiled, prog.needs(needs))
        if over:
            return _plans.settle(self, over, lambda: self.ensemble(
                seeds, params, x0, runs=runs, max_log_bytes=max_log_bytes, chunk=asked))
        if self.check_finite:
            _check_finite(res)
        return res

    # --------------------------------------------------------- gradients
    def _split_wrt(self, wrt):
        cd = self.compiled
        if isinstance(wrt, str):
            wrt = [wrt]
        params, states = [], []
        for w in wrt:
            w = str(w)
            if w.endswith("@x0"):
                path = w[:-3]
                bpath, _, nm = path.rpartition(".")
                i = cd.index(bpath)
                b = cd.blocks[i]
                if nm not in b._init or nm in b._random or b._init[nm].dtype.kind != "f":
                    raise ParameterError("no such float state to differentiate",
                                         block=bpath, param=nm,
                                         expected=sorted(k for k, v in b._init.items()
                                                         if v.dtype.kind == "f"
                                                         and k not in b._random), found=nm)
                states.append((w, i, nm))
            else:
                i, name = cd.param_index(w)
                params.append((w, f"{cd.names[i]}.{name}"))
        if not params and not states:
            raise ParameterError("nothing to differentiate", param="wrt",
                                 expected="a list of 'block.param' or 'block.state@x0'")
        return params, states

    def value_and_grad(self, cost, wrt, params=None, x0=None, seed=None, *,
                       checkpoint=True):
        """``(cost value, {name: gradient})`` by reverse mode through the run.

        ``cost(res)`` gets a :class:`Results` whose arrays are JAX arrays
        (write it with ``jax.numpy``) and returns a scalar; ``wrt`` names
        numeric parameters (``"drive.gain"``) and initial states
        (``"fleet.pose@x0"``). ``checkpoint`` recomputes the steps between
        log samples on the backward pass instead of storing them (memory
        ~ one log interval of states instead of the whole run).

        The compiled gradient is cached per ``cost`` object: pass the same
        function (not a new ``lambda`` each call) to avoid recompiling.
        """
        jax = _jax.jax()
        seed = self.seed if seed is None else int(seed)
        pw, sw = self._split_wrt(wrt)
        theta, _ = self._theta(params)
        x0vals, _ = self._x0_values(x0)
        X0 = self._states(x0vals, [seed])
        diff = ({key: theta[key] for _w, key in pw},
                {w: X0[i][nm] for w, i, nm in sw})
        prog = self.program
        runner = self

        def build():
            def f(diff, theta, X0):
                th = {**theta, **diff[0]}
                X = [dict(x) for x in X0]
                for w, i, nm in sw:
                    X[i][nm] = diff[1][w]
                logs, XF, needs = prog.run(th, X, remat=checkpoint)
                res = runner._results(list(logs), XF, {"backend": "jax", "traced": True})
                val = cost(res)
                if np.shape(val) != ():
                    raise ParameterError("the cost must return a scalar", param="cost",
                                         found=f"shape {np.shape(val)}")
                return val, needs
            return jax.value_and_grad(f, has_aux=True)

        exe, _ = prog.executable(("grad", cost, tuple(pw), tuple(w for w, *_ in sw),
                                  bool(checkpoint)), build, (diff, theta, X0),
                                 self.compiled, self.cache)
        with _jax.x64(prog.x64):
            (val, needs), g = exe(diff, theta, X0)
        grads = {w: np.asarray(g[0][key]) for w, key in pw}
        grads.update({w: np.asarray(g[1][w]) for w, *_ in sw})
        over = _plans.overflows(self.compiled, prog.needs(needs))
        if over:
            return _plans.settle(self, over, lambda: self.value_and_grad(
                cost, wrt, params, x0, seed, checkpoint=checkpoint))
        return float(val), grads

    def grad(self, cost, wrt, params=None, x0=None, seed=None, *, checkpoint=True):
        """``{name: gradient}``; see :meth:`value_and_grad`."""
        return self.value_and_grad(cost, wrt, params, x0, seed, checkpoint=checkpoint)[1]


def _axes_key(tree):
    if isinstance(tree, dict):
        return tuple(sorted((k, _axes_key(v)) for k, v in tree.items()))
    if isinstance(tree, list):
        return tuple(_axes_key(v) for v in tree)
    return tree


def _canon_np(dtype, x64):
    dt = np.dtype(dtype)
    if x64:
        return dt
    return {np.dtype("float64"): np.dtype("float32"), np.dtype("int64"): np.dtype("int32"),
            np.dtype("uint64"): np.dtype("uint32")}.get(dt, dt)


def _count_runs(seeds, params, x0, runs):
    if runs is not None:
        return int(runs)
    if seeds is not None:
        return len(list(seeds))
    for d in (params or {}), (x0 or {}):
        for v in d.values():
            if np.ndim(v) >= 1:
                return int(np.shape(v)[0])
    raise ParameterError("cannot tell how many runs", param="seeds",
                         hint="pass seeds=range(R), runs=R or per-run values")
