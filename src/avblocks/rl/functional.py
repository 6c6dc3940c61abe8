"""A diagram as a pure environment: ``reset(key, params)``, ``step(key, state, action, params)``.

This is the form every other environment in :mod:`avblocks.rl` wraps, and
the one to jit a whole training loop over (gymnax / JaxMARL style)::

    env = rl.functional("navigation")                 # JAX engine, float32
    state, obs = env.reset(key)                       # obs (N, obs_dim)
    state, obs, reward, done, info = env.step(key, state, action)

One control step writes the agents' actions into the diagram's
:class:`~avblocks.blocks.Action` block and advances ``substeps`` major
steps of the engine (the same semantics as a run: outputs, discrete
updates, one solver step; see :mod:`avblocks.core.simulator`), then
computes the observation, the reward and the termination from the outputs
at the new time. ``step`` resets an episode that ended (the returned
observation is then the new episode's first; ``info["final_obs"]`` holds
the last one), so a rollout is a plain ``lax.scan``.

Everything a run owns lives in :class:`EnvState`: the blocks' states (random
keys included), the outputs at the current time, the numeric parameters of
the episode (``theta``: domain randomization is a different ``params`` at
each reset) and the step counters. Nothing is global and nothing is
mutated, so ``jax.vmap`` over keys gives independent copies.

Neighbour searches (JAX): the env plans them as a compiled run does, from
the diagram's inputs at ``t0`` (or the plan a compiled run of the same
structure grew), and the state carries what they needed (``needs``, a
running maximum over steps and episodes; no host call per step). A plan
too small for what an episode met is never silent: the Gymnasium,
PettingZoo and vector wrappers and :meth:`FunctionalEnv.rollout` check it
after each reset and step (rollout) and raise
:class:`~avblocks.core.errors.SimulationError`; code that jits its own
loop calls :meth:`FunctionalEnv.check` on a state it gets back.

Observations are the named output ports, each reshaped to ``(N, -1)`` and
concatenated along the last axis (or a function of the step's signals).
Rewards are ``(N,)`` per agent; an episode ends when ``done`` holds for
every agent (termination) or after ``max_steps`` control steps
(truncation). ``done`` is reported per agent as the episode's flag.
"""

from __future__ import annotations

import math
import zlib
from typing import Any, NamedTuple

import numpy as np

from ..core.diagram import CompiledDiagram, Diagram, PortRef
from ..core.errors import ParameterError, WiringError
from . import _engine


class EnvState(NamedTuple):
    """Everything one environment copy carries from step to step (a pytree)."""

    X: list            # per block: {state name: array}, random keys included
    Y: list            # per block: {output name: array} at the current time
    theta: dict        # {"block.param": array}: this episode's numeric parameters
    k: Any             # major step index (int)
    steps: Any         # control steps taken in this episode (int)
    key: Any           # the episode's key (for the next automatic reset)
    #: JAX: the most each neighbour search needed since the env's first reset
    #: (a tally, see :meth:`FunctionalEnv.check`); None without searches / NumPy
    needs: Any = None


class Signals(dict):
    """The step's outputs by ``"block.port"`` path (what reward/done see)."""

    def __missing__(self, k):
        import difflib
        close = difflib.get_close_matches(str(k), list(self), n=1)
        raise WiringError("no such output", found=k, expected="'block.port'",
                          hint=f"did you mean '{close[0]}'?" if close else None)


def _path(ref):
    if isinstance(ref, PortRef):
        return ref.path
    return str(ref)


class Task:
    """What turns a diagram into an environment (see :func:`functional`).

    Parameters
    ----------
    diagram : Diagram
    act : str
        Name of the :class:`~avblocks.blocks.Action` block (or its port
        ``"block.action"``); one agent per row of its output.
    observe : str, list of str, or callable
        Output ports ``"block.port"`` of shape ``(N, ...)``, concatenated per
        agent; or ``observe(sig, xp) -> (N, obs_dim)``.
    reward : str or callable
        An ``(N,)`` output port, or ``reward(sig, action, xp) -> (N,)``.
    done : str, callable or None
        An ``(N,)`` boolean output or ``done(sig, xp) -> (N,)``; the episode
        terminates when it holds for every agent. ``None``: only truncation.
    reset : callable, optional
        ``reset(key, xp) -> {"block.state" or "block.param": value}``: the
        random initial conditions of an episode (draw with
        :mod:`avblocks.core.rng` and ``xp`` so both engines run it).
    info : dict, optional
        ``{name: "block.port" or fn(sig, xp)}`` copied into ``info`` each step.
    dt : float
        Major step of the engine [s]; ``substeps`` of them make a control step.
    substeps : int
    max_steps : int
        Control steps per episode (truncation).
    solver : str
        ``"rk4"`` or ``"euler"``.
    """

    def __init__(self, diagram, *, act, observe, reward, done=None, reset=None, info=None,
                 dt=0.05, substeps=1, max_steps=200, solver="rk4"):
        if not isinstance(diagram, (Diagram, CompiledDiagram)):
            raise ParameterError("a Task needs a Diagram", param="diagram",
                                 expected="Diagram", found=type(diagram).__name__)
        self.diagram = diagram
        self.act = _path(act)
        self.observe = observe if callable(observe) else (
            [_path(observe)] if isinstance(observe, (str, PortRef)) else
            [_path(o) for o in observe])
        self.reward = reward if callable(reward) else _path(reward)
        self.done = done if (done is None or callable(done)) else _path(done)
        self.reset = reset
        self.info = {k: (v if callable(v) else _path(v)) for k, v in (info or {}).items()}
        self.dt = float(dt)
        self.substeps = int(substeps)
        self.max_steps = int(max_steps)
        self.solver = solver
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ParameterError("dt must be > 0", param="dt", found=dt)
        if self.substeps < 1 or self.max_steps < 1:
            raise ParameterError("substeps and max_steps must be >= 1", param="max_steps",
                                 found=(substeps, max_steps))

    def replace(self, **kw):
        """A copy with some settings changed."""
        new = Task.__new__(Task)
        new.__dict__.update(self.__dict__)
        for k, v in kw.items():
            if k not in self.__dict__:
                raise ParameterError("unknown Task setting", param=k,
                                     expected=sorted(self.__dict__))
            setattr(new, k, v)
        return new


class FunctionalEnv:
    """A :class:`Task` as pure ``reset``/``step`` functions (module docstring).

    Parameters
    ----------
    task : Task
    backend : ``"jax"`` (default) or ``"numpy"``
        JAX: traceable (jit, vmap, grad), float32. NumPy: the NumPy engine,
        float64, plain Python calls (same semantics, for checking).

    Attributes
    ----------
    n : int
        Agents.
    obs_dim, act_dim : int
    action_low, action_high : ndarray (act_dim,)
        From the Action block's ``low``/``high`` at build time.
    params : dict
        Default numeric parameters ``{"block.param": array}``.
    """

    def __init__(self, task, backend="jax"):
        if backend not in ("jax", "numpy"):
            raise ParameterError("unknown backend", param="backend",
                                 expected="'jax' or 'numpy'", found=backend)
        self.task = task
        self.backend = backend
        d = task.diagram
        self.cd = cd = d.build() if isinstance(d, Diagram) else d
        act = task.act
        if act in cd.names:
            ai = cd.index(act)
        else:
            ai, _ = cd.resolve(act)
        blk = cd.blocks[ai]
        if "value" not in blk._dstates or "action" not in blk._outputs:
            raise WiringError("act must name an Action block", block=cd.names[ai],
                              expected="blocks.Action", found=type(blk).__name__)
        self._ai = ai
        # blocks whose outputs change with the action within a step: the
        # Action block and its descendants through direct-feedthrough wires
        # (the rest of the state's outputs are already those at the step's
        # start; see step_env)
        down = {ai}
        for i in range(len(cd.blocks)):          # evaluation order: sources first
            srcs = cd.sources[i]
            ft = cd.blocks[i].feedthrough
            if any(inp in ft and s_ in down for inp, (s_, _o) in srcs.items()):
                down.add(i)
        self._after_action = frozenset(down)
        self.n = int(blk._outputs["action"].shape[0])
        self.act_dim = int(blk._outputs["action"].shape[1])
        self.action_low = np.asarray(blk.low, dtype=np.float32).copy()
        self.action_high = np.asarray(blk.high, dtype=np.float32).copy()
        self.params = {f"{nm}.{k}": np.asarray(v) for nm, b in zip(cd.names, cd.blocks)
                       for k, v in b.parameter_values().items()}
        self.dt = task.dt
        self.control_dt = task.dt * task.substeps
        self.max_steps = task.max_steps
        self._random = [(i, r) for i, (nm, b) in enumerate(zip(cd.names, cd.blocks))
                        for r in sorted(b._random)]
        self._solver = _engine.make_solver(task.solver)
        if backend == "jax":
            jax = _engine.jax()
            self.xp = jax.numpy
            _engine.plan_searches(cd, task.dt)
            self._rows = _engine.need_rows(cd)
            self._eng = _engine.traced_engine(cd, task.dt, jax.numpy,
                                              jax.dtypes.canonicalize_dtype)
        else:
            self.xp = np
            self._rows = {}
            self._eng = _engine.Engine(cd, task.dt, np)
        for p in ([] if callable(task.observe) else task.observe) + \
                [v for v in (task.reward, task.done, *task.info.values())
                 if isinstance(v, str)]:
            cd.resolve(p)            # a wrong port name fails here, in words
        # shapes from one NumPy evaluation (cheap; checks the task early)
        probe = self if backend == "numpy" else FunctionalEnv(task, "numpy")
        _, obs = probe.reset(_engine.rng.key(0, "probe"))
        if obs.ndim != 2 or obs.shape[0] != self.n:
            raise ParameterError("observations must have shape (N, obs_dim)",
                                 param="observe", expected=f"({self.n}, obs_dim)",
                                 found=obs.shape)
        self.obs_dim = int(obs.shape[1])

    def __repr__(self):
        return (f"FunctionalEnv({self.n} agents, obs {self.obs_dim}, act {self.act_dim}, "
                f"{self.max_steps} steps of {self.control_dt:g} s, {self.backend})")

    def validate_param(self, path, value):
        """``("block.param", checked value)``: the parameter's declared shape
        and bounds (ParameterError naming the block otherwise)."""
        i, name = self.cd.param_index(path)
        spec = self.cd.blocks[i]._params[name]
        return f"{self.cd.names[i]}.{name}", spec.validate(value, self.cd.names[i])

    # ------------------------------------------------------------ helpers
    def _asarray(self, v, like=None):
        xp = self.xp
        if like is not None:
            return xp.asarray(v, dtype=like.dtype)
        a = np.asarray(v) if not hasattr(v, "dtype") else v
        return xp.asarray(a)

    def _signals(self, Y):
        cd = self.cd
        return Signals({f"{cd.names[i]}.{o}": v for i, y in enumerate(Y)
                        for o, v in y.items()})

    def _params(self, params, base=None):
        """``base`` (default: every declared value) with ``params`` set."""
        if base is None:
            base = {k: self.xp.asarray(v) for k, v in self.params.items()}
        theta = dict(base)
        for path, v in (params or {}).items():
            i, name = self.cd.param_index(path)
            key = f"{self.cd.names[i]}.{name}"
            theta[key] = self.xp.asarray(v, dtype=theta[key].dtype)
        return theta

    def _bind(self, theta):
        cd = self.cd
        per = {}
        for path, v in theta.items():
            bpath, _, nm = path.rpartition(".")
            i = cd.index(bpath)
            per.setdefault(i, (cd.blocks[i], {}))[1][nm] = v
        return _engine.bound_parameters(list(per.values()))

    def _observe(self, sig):
        xp = self.xp
        ob = self.task.observe
        if callable(ob):
            o = ob(sig, xp)
        else:
            o = xp.concatenate([xp.reshape(sig[p], (self.n, -1)) for p in ob], axis=-1)
        return xp.asarray(o, dtype=xp.float32)

    def _value(self, spec, sig, *args):
        if callable(spec):
            return spec(sig, *args, self.xp)
        return sig[spec]

    # -------------------------------------------------------------- reset
    def reset(self, key, params=None):
        """``(state, obs)`` of a new episode: parameters = defaults, then
        ``params``, then the task's random initial conditions drawn from
        ``key`` (an avblocks/JAX raw key, ``uint32[2]``)."""
        xp, cd, rng = self.xp, self.cd, _engine.rng
        key = xp.asarray(key, dtype=xp.uint32)
        k_ep, k_init, k_blocks = rng.split(key, xp, 3)
        theta = self._params(params)
        X = [b.initial_state() for b in cd.blocks]
        if self.task.reset is not None:
            over = self.task.reset(k_init, xp)
            for path, v in over.items():
                bpath, _, nm = str(path).rpartition(".")
                i = cd.index(bpath)
                b = cd.blocks[i]
                if nm in b._params:
                    theta[f"{bpath}.{nm}"] = xp.asarray(v, dtype=theta[f"{bpath}.{nm}"].dtype)
                elif nm in b._init and nm not in b._random:
                    X[i] = {**X[i], nm: v}
                else:
                    raise ParameterError("reset() returned an unknown name", block=bpath,
                                         param=nm, expected="a state or numeric parameter "
                                         f"of the block: {sorted(set(b._init) | set(b._params))}")
        if self._random:
            ks = rng.split(k_blocks, xp, len(self._random) + 1)
            for (i, r), kk in zip(self._random, ks[1:]):
                salt = zlib.crc32(f"{cd.names[i]}.{r}".encode()) & 0x7FFFFFFF
                X[i] = {**X[i], r: _fold(kk, salt, xp)}
        X = [{k: self._cast(v, cd.blocks[i]._init[k].dtype) for k, v in x.items()}
             for i, x in enumerate(X)]
        with self._bind(theta), self._tally(None) as tl:
            Y = self._eng.all_outputs(0.0, X, [dict() for _ in cd.blocks])
        sig = self._signals(Y)
        obs = self._observe(sig)
        zero = xp.asarray(0, dtype=xp.int32)
        return EnvState(X, Y, theta, zero, zero, k_ep, self._needs(tl)), obs

    def _tally(self, needs):
        """The tally the searches report to while a reset or step traces
        (``needs``: carried in, None: from zero); a no-op without searches."""
        if not self._rows:
            return _engine.tally({}, None)
        if needs is None:
            needs = self.xp.zeros((len(self._rows), 4), self.xp.asarray(0.0).dtype)
        return _engine.tally(self._rows, needs)

    def _needs(self, tl):
        return None if tl is None else tl.value

    def overflows(self, state):
        """``[(block name, search, need, message)]`` of the neighbour
        searches whose plan was too small for what ``state`` (or states
        stacked on leading axes) met since the first reset: their results
        were cut short. Empty when all held (and under NumPy, which sizes
        each search itself). Host side: reads ``state.needs``."""
        if not self._rows or state.needs is None:
            return []
        return _engine.overflows(self.cd, self._rows, state.needs)

    def check(self, state):
        """Raise :class:`~avblocks.core.errors.SimulationError` naming the
        block and the sizes when :meth:`overflows` finds any (call it on a
        state a jitted loop returns); returns ``state``."""
        over = self.overflows(state)
        if over:
            from ..core.errors import SimulationError
            names = ", ".join(f"'{n}' ({m})" for n, _, _, m in over)
            raise SimulationError(
                "a neighbour search of the environment overflowed its static plan, so "
                f"its results were cut short: {names}", block=over[0][0],
                hint="give the block's search a larger capacity= (and hits=), or plan "
                     "it from a crowded state: a compiled run of the diagram that "
                     "re-plans keeps its grown plan for environments made after it")
        return state

    def _cast(self, v, dtype):
        xp = self.xp
        dt = np.dtype(dtype)
        if self.backend == "jax":
            jax = _engine.jax()
            dt = jax.dtypes.canonicalize_dtype(dt)
        return xp.asarray(v, dtype=dt)

    # --------------------------------------------------------------- step
    def step_env(self, state, action, params=None):
        """One control step without automatic reset:
        ``(state, obs, reward, done, info)``."""
        xp, eng, solver = self.xp, self._eng, self._solver
        # only the given parameters change: the episode's drawn values stay
        theta = state.theta if params is None else self._params(params, state.theta)
        X = list(state.X)
        ai = self._ai
        a = xp.reshape(xp.asarray(action), (self.n, self.act_dim))
        X[ai] = {**X[ai], "value": xp.asarray(a, dtype=X[ai]["value"].dtype)}
        Y, k, dt = state.Y, state.k, self.dt
        with self._bind(theta), self._tally(state.needs) as tl:
            X, Y, k = _engine.advance(eng, solver, self._after_action, X, Y, k, dt,
                                      self.task.substeps)
            sig = self._signals(Y)
            obs = self._observe(sig)
            act = sig[f"{self.cd.names[ai]}.action"]
            reward = xp.asarray(self._value(self.task.reward, sig, act), dtype=xp.float32)
            reward = xp.broadcast_to(reward, (self.n,))
            if self.task.done is None:
                term = xp.zeros((self.n,), dtype=bool)
            else:
                term = xp.broadcast_to(xp.asarray(self._value(self.task.done, sig), bool),
                                       (self.n,))
            info = {name: self._value(spec, sig) for name, spec in self.task.info.items()}
        steps = state.steps + 1
        terminated = xp.all(term)
        truncated = steps >= self.max_steps
        info["agent_done"] = term
        info["terminated"] = terminated
        info["truncated"] = truncated & ~terminated
        done = xp.broadcast_to(terminated | truncated, (self.n,))
        new = EnvState(X, Y, theta, k, steps, state.key, self._needs(tl))
        return new, obs, reward, done, info

    def step(self, key, state, action, params=None):
        """One control step; an episode that ends is reset (from the state's
        episode key folded with ``key``) and ``info["final_obs"]`` holds its
        last observation. Returns ``(state, obs, reward, done, info)``."""
        xp, rng = self.xp, _engine.rng
        new, obs, reward, done, info = self.step_env(state, action, params)
        info["final_obs"] = obs
        k_next, k_reset = rng.split(xp.asarray(key, dtype=xp.uint32), xp, 2)
        rkey = _fold(k_reset, 0, xp) if self.backend == "numpy" else \
            _engine.jax().random.fold_in(k_reset, 0)
        rstate, robs = self.reset(_mix(state.key, rkey, xp), params)
        ended = done[0]
        if self.backend == "numpy":
            if bool(ended):
                return rstate, robs, reward, done, info
            return new, obs, reward, done, info
        jax = _engine.jax()
        pick = lambda a, b: xp.where(ended, a, b)  # noqa: E731
        out = jax.tree_util.tree_map(pick, rstate, new)
        if new.needs is not None:        # the tally spans episodes
            out = out._replace(needs=xp.maximum(new.needs, rstate.needs))
        return out, pick(robs, obs), reward, done, info

    # ----------------------------------------------------------- rollouts
    def rollout(self, key, policy, steps, params=None, policy_params=None):
        """``steps`` control steps from a fresh episode under
        ``policy(policy_params, obs, key) -> action`` as one ``lax.scan``
        (JAX backend): returns ``(obs, actions, rewards, dones)`` stacked
        over time. Called outside a JAX transformation, it checks the
        neighbour searches' needs afterwards (:meth:`check`)."""
        jax = _engine.jax()
        jnp = jax.numpy
        k0, k1 = jax.random.split(jnp.asarray(key, dtype=jnp.uint32))
        state, obs = self.reset(k0, params)

        def body(carry, k):
            state, obs = carry
            ka, ks = jax.random.split(k)
            a = policy(policy_params, obs, ka)
            state, obs2, r, d, _ = self.step(ks, state, a, params)
            return (state, obs2), (obs, a, r, d)

        (last, _), out = jax.lax.scan(body, (state, obs), jax.random.split(k1, steps))
        if last.needs is not None and not isinstance(last.needs, jax.core.Tracer):
            self.check(last)
        return out


def _fold(k, salt, xp):
    """A key derived from ``k`` and an integer (both engines)."""
    if getattr(xp, "__name__", "numpy") == "numpy":
        k = np.asarray(k, dtype=np.uint32)
        return _engine.rng.key(int(k[0]) ^ (int(k[1]) << 32), int(salt))
    return _engine.jax().random.fold_in(k, salt)


def _mix(a, b, xp):
    """Combine two keys into one (both engines)."""
    if getattr(xp, "__name__", "numpy") == "numpy":
        a = np.asarray(a, dtype=np.uint32)
        b = np.asarray(b, dtype=np.uint32)
        return _engine.rng.key(int(a[0]) ^ (int(b[0]) << 32), int(a[1] ^ b[1]))
    return xp.bitwise_xor(a, b)
