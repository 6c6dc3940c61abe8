"""User-facing compiled runs: :func:`compile` -> :class:`~avblocks.core.compiled.runner.Runner`,
the ``backend="jax"`` path of :func:`avblocks.simulate`
(:func:`simulate_compiled`), and :func:`grad`."""

from __future__ import annotations

import weakref

from ..diagram import CompiledDiagram, Diagram, PortRef
from ..errors import CompileError, ParameterError
from ..runguard import finite_number, whole_steps
from ..solvers import make_solver
from . import _jax
from . import devices as _devices
from . import persist as _persist
from . import plans as _plans
from . import segments as _segments
from .program import Program, get_program
from .runner import Runner, _solver_key
from .structure import Snapshot, diagram_key

_DTYPES = {"float64": True, "float32": False}
_UNTRACEABLE_HINT = ("run this diagram with backend='numpy' (simulate(..., "
                     "backend='numpy')); the compiled backend needs blocks whose math "
                     "is pure `xp` code")


def _log_spec(compiled, log):
    """(indices, names, port specs, aliases) of what to log (as the NumPy path)."""
    from ..runguard import default_log
    if log is None:
        refs = default_log(compiled)
    elif isinstance(log, (str, PortRef)):
        refs = [log]
    else:
        refs = list(log)
    idx, names, specs, aliases = [], [], [], {}
    for r in refs:
        i, o = compiled.resolve(r)
        name = f"{compiled.names[i]}.{o}"
        if name in names:
            continue
        idx.append((i, o))
        names.append(name)
        specs.append(compiled.blocks[i]._outputs[o])
        alias = r.path if isinstance(r, PortRef) else str(r)
        if alias != name:
            aliases[alias] = name
    return idx, names, specs, aliases


def _check_traceable(compiled):
    bad = [(n, type(b).__name__, "has side effects (I/O, drawing, hardware)")
           for n, b in zip(compiled.names, compiled.blocks) if b.side_effects]
    bad += [(n, type(b).__name__, "runs NumPy-only code (declares traceable = False)")
            for n, b in zip(compiled.names, compiled.blocks)
            if not getattr(b, "traceable", True) and not b.side_effects]
    if bad:
        n, cls, why = bad[0]
        others = "" if len(bad) == 1 else f"; also: {', '.join(b[0] for b in bad[1:])}"
        raise CompileError(f"{cls} cannot be compiled: it {why}{others}", block=n,
                           hint=_UNTRACEABLE_HINT)


def compile(diagram, t_final, dt=0.01, solver="rk4", *, log=None, log_every=1, t0=0.0,
            seed=0, backend="jax", dtype="float64", check_finite=True, devices=None,
            on_overflow="replan", cache=None, shard="auto"):
    """Compile ``diagram`` once for runs of ``t_final`` (JAX: ``jit`` of a
    nested ``lax.scan``) and return a :class:`Runner`.

    Parameters
    ----------
    diagram : Diagram or CompiledDiagram
    t_final, dt, solver, t0 : as :func:`avblocks.simulate` (fixed-step
        solvers only: ``"rk4"``, ``"euler"`` or a fixed-step Solver).
    log : list of ports or ``"block.port"`` strings, optional
        What the runs record (default: every ``pose``/``position`` output).
    log_every : int
        Record every ``log_every``-th major step (the only copy of the log).
    seed : int
        Default seed of the runs.
    backend : ``"jax"``
    dtype : ``"float64"`` (default) or ``"float32"``
        float64 matches the NumPy engine to round-off (1e-9 on the test
        diagrams). float32 halves memory and is faster on GPUs, but drifts
        from the float64 run: measured over 30 s (3000 steps) of 1000
        unicycles in a 100 m square, up to 1.1 cm (median 1 mm) under the
        go-to-goal law and 2 mm on open-loop circles (docs/compiled.md).
        Random blocks draw from ``jax.random`` in either precision.
    check_finite : bool
        After a run, raise :class:`SimulationError` (with the results) if a
        logged signal or the final state is NaN/inf.
    on_overflow : ``"replan"`` (default) or ``"raise"``
        What a run does when a block's neighbour search needed more than the
        static plan made from the initial inputs: warn, re-plan, compile
        again once and repeat the run; or raise :class:`SimulationError`
        naming the block and the sizes (see
        :mod:`avblocks.core.compiled.plans`).
    devices : None, int or list of JAX devices
        Where the runs execute (default: every local device of JAX's
        default backend). With several, a run of at least
        ``devices.MIN_AGENTS_TO_SPLIT`` agents is split along its agent
        axis and an ensemble along its run axis (see
        :mod:`avblocks.core.compiled.devices`); ``devices=1`` keeps
        everything on one device.
    shard : ``"auto"`` (default) or ``"agents"``
        How a single run uses several devices. ``"auto"``: its agent axis is
        split only when the agents never interact (no exchange between
        devices), else it runs on one device. ``"agents"``: split whatever
        the agents do (one swarm across devices): each neighbour search
        sorts the points on every device and answers each device's share
        of the queries, a strip of space, there; the run equals the
        one-device run (see :mod:`avblocks.core.compiled.devices`). The
        agent count must divide evenly over the devices.
    cache : None, bool or folder
        Where the compiled programs and grown neighbour-search plans are
        kept across processes (:mod:`avblocks.core.compiled.persist`):
        None (default) the user's cache folder
        (:func:`~avblocks.core.compiled.cache_dir`) unless
        ``$AVBLOCKS_CACHE`` is ``off``; ``False`` nowhere (memory only);
        ``True`` the cache folder even so; or a folder. A second process
        with the same diagram then reads the program and starts from the
        grown plans: no compile.

    Notes
    -----
    The compiled program is shared by every diagram with the same structure
    (block types, wiring, shapes, sample times, non-parameter attributes),
    step count and log: numeric parameters, initial states and seeds are its
    arguments, so new values never recompile. A block that cannot be traced
    raises :class:`CompileError` naming it.

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> d = av.Diagram()
    >>> c = d.add(av.blocks.Constant([[1.0]]), name="c")
    >>> g = d.add(av.blocks.Gain(2.0), name="g")
    >>> i = d.add(av.blocks.Integrator([[0.0]]), name="i")
    >>> _ = d.connect(c.y, g.u), d.connect(g.y, i.u)
    >>> run = av.compile(d, 1.0, dt=0.1, log=[i.y])
    >>> float(run(params={"g.k": 3.0})[i.y][-1, 0, 0])
    3.0
    """
    if backend not in ("jax",):
        raise ParameterError("unknown compiled backend", param="backend",
                             expected="'jax'", found=backend)
    if dtype not in _DTYPES:
        raise ParameterError("unknown dtype", param="dtype",
                             expected="'float64' or 'float32'", found=dtype)
    jax = _jax.jax()
    cd = diagram.build() if isinstance(diagram, Diagram) else diagram
    if not isinstance(cd, CompiledDiagram):
        raise ParameterError("compile needs a Diagram", param="diagram",
                             expected="Diagram", found=type(diagram).__name__)
    # the same checks as every engine (core.runguard): finite numbers, dt > 0,
    # a whole number of steps (never a silently shortened run)
    dt = finite_number(dt, "dt")
    if not dt > 0:
        raise ParameterError("major step must be a positive number", param="dt",
                             expected="> 0", found=dt)
    t0 = finite_number(t0, "t0")
    nsteps = whole_steps(t0, finite_number(t_final, "t_final"), dt)
    try:
        log_every = int(log_every)
    except (TypeError, ValueError):
        log_every = 0
    if log_every < 1:
        raise ParameterError("log_every must be >= 1", param="log_every",
                             expected=">= 1", found=log_every)
    solv = make_solver(solver)
    if not solv.fixed_step:
        raise CompileError("the compiled backend runs fixed-step solvers only",
                           param="solver", expected="'rk4' or 'euler'", found=solver,
                           hint="use backend='numpy' for solve_ivp methods")
    _check_traceable(cd)
    _plans.check_mode(on_overflow)
    root = _persist.use(cache)
    store = _plans.plan_store(root)
    _plans.plan_searches(cd, dt=dt, t0=t0, seed=seed, store=store)
    idx, names, specs, aliases = _log_spec(cd, log)
    x64 = _DTYPES[dtype]
    key = (diagram_key(cd), nsteps, log_every, tuple(names), _solver_key(solv), dt,
           float(t0), x64, str(jax.default_backend()))
    prog = get_program(key, lambda: Program(cd, dt=dt, t0=t0, nsteps=nsteps,
                                            log_every=log_every, log_idx=idx,
                                            solver=solv, x64=x64))
    runner = Runner(cd, prog, names=names, specs=specs, aliases=aliases, seed=seed,
                    dtype=dtype, check_finite=check_finite, solver_name=solv.name,
                    devices=_devices.resolve(devices), shard=shard)
    runner.on_overflow = on_overflow
    runner.struct = key[0]          # the structure it was compiled for
    runner.cache, runner.plan_store = root, store
    return runner


#: Diagram -> the runner its last ``simulate(backend="jax")`` made, with what
#: it was made from: ``(settings, wiring stamp, structure key, snapshot of
#: the blocks, runner)``
_LAST: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _settings(t_final, dt, solver, log, log_every, t0, dtype, check_finite, cache=None,
              devices=None, shard="auto"):
    """Hashable run settings of a ``simulate`` call, or None (not cached)."""
    try:
        if log is not None and not isinstance(log, (str, PortRef)):
            log = tuple(log)
        key = (float(t_final), float(dt), solver if isinstance(solver, str)
               else _solver_key(solver), log, int(log_every), float(t0), dtype,
               bool(check_finite), cache if isinstance(cache, (bool, type(None)))
               else str(cache),
               devices if devices is None or isinstance(devices, int)
               else tuple(d.id for d in devices), shard)
        hash(key)
    except (TypeError, ValueError):
        return None
    return key


def _last_runner(diagram, settings):
    """The runner of ``diagram``'s previous compiled run when nothing it was
    made from changed: the same settings, no wiring change since (the
    diagram's stamp) and the same structure key (every block's structural
    attributes, looked at afresh: an in-place change of any is seen; a
    :class:`~.structure.Snapshot` says quickly that nothing changed, else
    the key is worked out).
    Parameter values and initial states are read by the runner at each call."""
    last = _LAST.get(diagram) if isinstance(diagram, Diagram) else None
    if last is None or settings is None:
        return None
    was, stamp, struct, snap, runner = last
    if was != settings or stamp != diagram._stamp:
        return None
    if not snap.matches():
        # something changed: structure, or only values (a parameter's bounds)
        if diagram_key(runner.compiled) != struct:
            return None
        _LAST[diagram] = (was, stamp, struct, Snapshot(runner.compiled), runner)
    return runner


def simulate_compiled(diagram, t_final, dt=0.01, solver="rk4", *, log=None, log_every=1,
                      seed=0, t0=0.0, realtime=None, progress=None, check_finite=True,
                      max_log_bytes=2 * 1024**3, params=None, x0=None, backend="jax",
                      dtype="float64", cache=None, devices=None, shard="auto"):
    """:func:`avblocks.simulate` with ``backend="jax"`` (same arguments and
    Results; plus ``dtype``). ``realtime`` pacing needs the NumPy backend.
    ``progress`` (a callable ``progress(step, steps)`` or ``True``, a bar)
    runs the compiled program in segments, reporting between them and
    stoppable by a ``KeyboardInterrupt`` raised there, as the NumPy engine
    (:mod:`avblocks.core.compiled.segments`); ``None`` or ``False`` runs it
    in one call. A second call on the same
    diagram with the same settings reuses the first call's runner (see
    :func:`_last_runner`), so it costs a structure check, not a compile.
    ``cache`` (default None: the user's cache folder unless
    ``$AVBLOCKS_CACHE=off``; ``False``: none) keeps the compiled program and
    grown plans for the next process, as :func:`compile` says; ``devices``
    and ``shard`` place the run as :func:`compile` does."""
    if realtime is not None:
        raise ParameterError("real-time pacing needs the NumPy backend", param="realtime",
                             hint="use backend='numpy' to pace a run to the clock")
    _segments.reporter(progress)        # a wrong progress= fails before compiling
    if log is not None and not isinstance(log, (str, PortRef)):
        log = list(log)                 # read once (it may be an iterator)
    settings = _settings(t_final, dt, solver, log, log_every, t0, dtype, check_finite,
                         cache, devices, shard) if backend == "jax" else None
    runner = _last_runner(diagram, settings)
    if runner is None:
        runner = compile(diagram, t_final, dt, solver, log=log, log_every=log_every,
                         t0=t0, seed=seed, backend=backend, dtype=dtype,
                         check_finite=check_finite, cache=cache, devices=devices,
                         shard=shard)
        if settings is not None and isinstance(diagram, Diagram):
            _LAST[diagram] = (settings, diagram._stamp, runner.struct,
                              Snapshot(runner.compiled), runner)
    p = runner.program
    need = runner.log_bytes
    if need > max_log_bytes:
        raise ParameterError(f"the log would take {need / 1e9:.2f} GB", param="log",
                             expected=f"<= {max_log_bytes / 1e9:.2f} GB",
                             found=f"{len(runner.specs)} signals x {p.nlog} samples",
                             hint="log fewer signals or decimate with log_every")
    res = runner(params=params, x0=x0, seed=seed, progress=progress)
    last = _LAST.get(diagram) if isinstance(diagram, Diagram) else None
    if last is not None and last[4] is runner and last[2] != runner.struct:
        # the run grew a plan (a new structure): the next call reuses the
        # runner as it is now
        _LAST[diagram] = (settings, diagram._stamp, runner.struct,
                          Snapshot(runner.compiled), runner)
    return res


def grad(cost, diagram, wrt, t_final, dt=0.01, solver="rk4", *, log=None, log_every=1,
         params=None, x0=None, seed=0, t0=0.0, dtype="float64", checkpoint=True,
         return_value=False):
    """Gradients of ``cost(results)`` by reverse mode through a whole run.

    ``wrt`` names numeric parameters (``"drive.gain"``) and initial states
    (``"fleet.pose@x0"``); returns ``{name: gradient array}`` (and the cost
    with ``return_value=True``). ``cost`` receives :class:`Results` holding
    JAX arrays: write it with ``jax.numpy``. Other arguments as
    :func:`compile` and :meth:`Runner.value_and_grad`.

    Examples
    --------
    >>> import jax.numpy as jnp, avblocks as av
    >>> d = av.Diagram()
    >>> c = d.add(av.blocks.Constant([[1.0]]), name="c")
    >>> g = d.add(av.blocks.Gain(2.0), name="g")
    >>> i = d.add(av.blocks.Integrator([[0.0]]), name="i")
    >>> _ = d.connect(c.y, g.u), d.connect(g.y, i.u)
    >>> gr = av.grad(lambda r: r[i.y][-1, 0, 0] ** 2, d, ["g.k"], 1.0, dt=0.1, log=[i.y])
    >>> round(float(gr["g.k"]), 9)      # d/dk (k t)^2 at t = 1, k = 2
    4.0
    """
    runner = compile(diagram, t_final, dt, solver, log=log, log_every=log_every, t0=t0,
                     seed=seed, dtype=dtype)
    val, g = runner.value_and_grad(cost, wrt, params, x0, seed, checkpoint=checkpoint)
    return (val, g) if return_value else g
