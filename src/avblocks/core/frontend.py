"""The front end: :func:`simulate` picks an engine from its arguments and runs it.

The engine contract
-------------------
An engine is one function (a module's ``run``, named ``"module:function"``
in :data:`ENGINES` and imported only when first used)::

    run(diagram, t_final, dt, solver, *, log, log_every, seed, t0, realtime,
        progress, check_finite, max_log_bytes, params, x0, **options) -> Results

It takes the arguments of :func:`simulate` (``log_every=None`` means "every
step unless the log would not fit"), checks them (the shared run guard,
:mod:`avblocks.core.runguard`, says what each means), refuses what it
cannot do with a :class:`ParameterError`, and returns
:class:`~avblocks.core.results.Results` (with ``final_state`` when it has
one). Options of its own (``dtype`` for the
compiled engine, ``live`` for the live one) come as keywords.

The engines below know nothing of this module and do not call one another:
the NumPy engine (:mod:`avblocks.core.run_loop`), the compiled JAX engine
(:mod:`avblocks.core.compiled`) and the live browser engine
(:mod:`avblocks.viz.live`, which steps the NumPy engine's
:class:`~avblocks.core.simulator.Simulator` paced by the page; it sits in a
layer *above* this one, which is why engines are named here, not
imported). A new engine is one new module plus :func:`register_engine`.

An engine that can also compile ahead of time (a diagram once, many runs)
offers ``compile(diagram, t_final, dt, solver, *, log, log_every, t0, seed,
backend, dtype, check_finite, devices) -> Runner``, named in
:data:`COMPILERS`; :func:`compile` picks it by ``backend``.
"""

from __future__ import annotations

import importlib

from .errors import ParameterError

#: engine name -> ``"module:function"`` implementing the contract above
ENGINES = {
    "numpy": "avblocks.core.run_loop:run",
    "jax": "avblocks.core.compiled.entry:run",
    "live": "avblocks.viz.live.engine:run",
}

#: backend name -> ``"module:function"`` compiling a diagram ahead of time
COMPILERS = {
    "jax": "avblocks.core.compiled.entry:compile",
}

_loaded: dict = {}


def register_engine(name, target) -> None:
    """Make ``simulate(..., backend=name)`` run ``target`` (a callable
    following the engine contract, or a ``"module:function"`` string)."""
    if callable(target):
        _loaded[name] = target
        ENGINES[name] = f"{target.__module__}:{target.__qualname__}"
    else:
        _loaded.pop(name, None)
        ENGINES[name] = str(target)


def _load(target):
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


def engine(name):
    """The run function of the engine called ``name`` (imported on first use)."""
    fn = _loaded.get(name) if isinstance(name, str) else None
    if fn is None:
        if not isinstance(name, str) or name not in ENGINES:
            raise ParameterError("unknown backend", param="backend",
                                 expected=" or ".join(repr(k) for k in ENGINES
                                                      if k != "live"),
                                 found=name)
        fn = _loaded[name] = _load(ENGINES[name])
    return fn


def compile(diagram, t_final, dt=0.01, solver="rk4", *, log=None, log_every=1, t0=0.0,
            seed=0, backend="jax", dtype="float64", check_finite=True, devices=None,
            on_overflow="replan", cache=None, shard="auto"):
    """Compile ``diagram`` once for runs of ``t_final`` with the compiling
    engine named by ``backend`` and return its :class:`Runner` (arguments:
    :func:`avblocks.core.compiled.compile`, the JAX engine's; ``cache``:
    where programs and plans are kept across processes, by default the
    user's cache folder; ``shard="agents"``: one run split over the
    devices)."""
    key = ("compile", backend) if isinstance(backend, str) else None
    fn = _loaded.get(key)
    if fn is None:
        if key is None or backend not in COMPILERS:
            raise ParameterError("unknown compiled backend", param="backend",
                                 expected=" or ".join(repr(k) for k in COMPILERS),
                                 found=backend)
        fn = _loaded[key] = _load(COMPILERS[backend])
    return fn(diagram, t_final, dt, solver, log=log, log_every=log_every, t0=t0, seed=seed,
              backend=backend, dtype=dtype, check_finite=check_finite, devices=devices,
              on_overflow=on_overflow, cache=cache, shard=shard)


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
    progress : bool or callable, optional
        Progress bar (default: only when stderr is a terminal and not in CI),
        or ``progress(step, steps)`` called about 100 times a run by the
        NumPy engine, and at least every 0.05 s of wall time (raising
        ``KeyboardInterrupt`` there stops the run as Ctrl-C does: the
        results so far come back, marked interrupted).
        ``backend="jax"`` with a callable or ``True`` runs the compiled
        program in segments and does the same between them (up to 50
        times a run, and segments of a slow run sized to take about 0.1 s
        each; :mod:`avblocks.core.compiled.segments`); without
        ``progress`` it runs in one call.
    check_finite : bool
        Stop at the first NaN/inf, naming the block and port.
    max_log_bytes : int
        Refuse a run whose log would exceed this much memory.
    params : dict, optional
        Numeric parameter values for this run, ``{"block.name": value}``
        (validated; the blocks' own values are restored afterwards).
    x0 : dict, optional
        Initial state values, ``{"block.state": value}``.
    backend : ``"numpy"`` (default), ``"jax"`` or a registered engine's name
        ``"jax"`` compiles the whole run (:mod:`avblocks.core.compiled`):
        same arguments and Results (plus ``res.final_state``), fixed-step
        solvers and traceable blocks only, no ``realtime``; it takes the
        options ``dtype="float32"`` (default ``"float64"``), ``cache``
        (default: compiled programs and grown plans kept in the user's cache
        folder, so the next process compiles nothing; ``cache=False`` or
        ``AVBLOCKS_CACHE=off`` opt out), ``devices`` and ``shard="agents"``
        (one swarm split over several devices). A second run of the same
        structure with other numeric values does not recompile.
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
    if live:
        if backend != "numpy" or backend_options:
            raise ParameterError("live=True runs the NumPy backend step by step",
                                 param="backend", expected="'numpy'", found=backend)
        name, backend_options = "live", {"live": live}
    else:
        name = backend
    return engine(name)(diagram, t_final, dt, solver, log=log, log_every=log_every,
                        seed=seed, t0=t0, realtime=realtime, progress=progress,
                        check_finite=check_finite, max_log_bytes=max_log_bytes,
                        params=params, x0=x0, **backend_options)
