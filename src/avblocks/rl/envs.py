"""PettingZoo and Gymnasium faces of a :class:`~avblocks.rl.functional.FunctionalEnv`.

- :class:`ParallelEnv` (PettingZoo): one agent id per vehicle, ``agent_0``...
- :class:`GymEnv` (Gymnasium ``Env``): a single-agent diagram.
- :class:`VectorEnv` (Gymnasium 1.x ``VectorEnv``): K copies stepped as one
  ``jax.vmap``-ed, jitted call (``backend="jax"``) or as one call on
  ``(K, ...)`` stacked arrays on the NumPy engine (``backend="numpy"``,
  :mod:`avblocks.rl.batched`: blocks that broadcast over a batch axis run
  once, the others once per copy). Autoreset mode ``SAME_STEP``: an
  episode that ends is reset within the same ``step`` call; the returned
  observation is the new episode's and ``infos["final_obs"]`` (masked by
  ``infos["_final_obs"]``) holds the last one of the old.

Seeding: ``reset(seed=s)`` starts the environment's key stream at
``rng.key(s, "rl")``; every later reset without a seed continues that
stream, so a seeded run is repeatable. The diagram's random blocks draw
from keys derived from the episode's key (see ``FunctionalEnv.reset``).
"""

from __future__ import annotations

import numpy as np

from . import _engine

_STREAM = "rl"


def _spaces():
    try:
        from gymnasium import spaces
    except ImportError as e:  # pragma: no cover - depends on the extra
        from ..core.errors import AvError
        raise AvError("avblocks.rl needs gymnasium: pip install 'avblocks[rl]'") from e
    return spaces


def _obs_box(fenv, shape):
    spaces = _spaces()
    return spaces.Box(-np.inf, np.inf, shape=shape, dtype=np.float32)


def _act_box(fenv, shape):
    spaces = _spaces()
    lo = np.broadcast_to(fenv.action_low, shape).astype(np.float32)
    hi = np.broadcast_to(fenv.action_high, shape).astype(np.float32)
    return spaces.Box(lo, hi, dtype=np.float32)


def _set_param(env, path, value):
    """Set a numeric parameter ``"block.param"`` for the episodes that
    follow (validated now; applied at the next reset)."""
    key, v = env.fenv.validate_param(path, value)
    env.params = {**(env.params or {}), key: v}


class _Stepper:
    """Single-copy reset/step on either engine, returning NumPy arrays."""

    def __init__(self, fenv):
        self.fenv = fenv
        self._key = _engine.rng.key(0, _STREAM)
        if fenv.backend == "jax":
            jax = _engine.jax()
            self._reset = jax.jit(fenv.reset)
            self._step = jax.jit(fenv.step_env)
        else:
            self._reset, self._step = fenv.reset, fenv.step_env
        self.state = None
        self.last_obs = np.zeros((fenv.n, fenv.obs_dim), dtype=np.float32)

    def seed(self, seed):
        self._key = _engine.rng.key(int(seed), _STREAM)

    def next_key(self):
        self._key, k = _engine.rng.split(self._key, np, 2)
        return np.asarray(k, dtype=np.uint32)

    def reset(self, params=None):
        self.state, obs = self._reset(self.next_key(), params)
        self.fenv.check(self.state)         # a search cut short is never silent
        self.last_obs = np.asarray(obs)
        return self.last_obs

    def step(self, action, params=None):
        a = np.asarray(action, dtype=np.float32).reshape(self.fenv.n, self.fenv.act_dim)
        a = np.clip(a, self.fenv.action_low, self.fenv.action_high)
        self.state, obs, r, d, info = self._step(self.state, a, params)
        self.fenv.check(self.state)
        info = {k: np.asarray(v) for k, v in info.items()}
        self.last_obs = np.asarray(obs)
        return self.last_obs, np.asarray(r), bool(info["terminated"]), \
            bool(info["truncated"]), info


def _import_pz():
    try:
        from pettingzoo import ParallelEnv as _PZ
    except ImportError as e:  # pragma: no cover - depends on the extra
        from ..core.errors import AvError
        raise AvError("parallel_env needs pettingzoo: pip install 'avblocks[rl]'") from e
    return _PZ


def _make_parallel_class():
    base = _import_pz()

    class ParallelEnv(base):
        """A diagram as a PettingZoo ``ParallelEnv`` (see :func:`avblocks.rl.parallel_env`).

        Agents ``agent_0 .. agent_{N-1}`` are the rows of the Action block;
        observation ``i`` is row ``i`` of the task's observation, action
        ``i`` row ``i`` of the Action block's value. All agents start and
        end an episode together (``terminations``/``truncations`` are the
        episode's flags); per-agent ``done`` flags of the task are in
        ``infos[agent]["agent_done"]``.
        """

        metadata = {"name": "avblocks_diagram", "render_modes": [], "is_parallelizable": True}

        def __init__(self, fenv, params=None):
            self.fenv = fenv
            self.params = params
            self.possible_agents = [f"agent_{i}" for i in range(fenv.n)]
            self.agents = []
            self._obs_spaces = {a: _obs_box(fenv, (fenv.obs_dim,))
                                for a in self.possible_agents}
            self._act_spaces = {a: _act_box(fenv, (fenv.act_dim,))
                                for a in self.possible_agents}
            self.observation_spaces = self._obs_spaces
            self.action_spaces = self._act_spaces
            self._stepper = _Stepper(fenv)
            self.render_mode = None

        def observation_space(self, agent):
            return self._obs_spaces[agent]

        def set_param(self, path, value):
            """Set a numeric parameter for the following episodes."""
            _set_param(self, path, value)

        def action_space(self, agent):
            return self._act_spaces[agent]

        def reset(self, seed=None, options=None):
            if seed is not None:
                self._stepper.seed(seed)
            params = (options or {}).get("params", self.params)
            obs = self._stepper.reset(params)
            self.agents = list(self.possible_agents)
            return ({a: obs[i] for i, a in enumerate(self.agents)},
                    {a: {} for a in self.agents})

        def step(self, actions):
            fenv = self.fenv
            a = np.zeros((fenv.n, fenv.act_dim), dtype=np.float32)
            for i, ag in enumerate(self.possible_agents):
                if ag in actions:
                    a[i] = np.asarray(actions[ag], dtype=np.float32).reshape(fenv.act_dim)
            obs, r, term, trunc, info = self._stepper.step(a, self.params)
            agents = list(self.agents)
            idx = {ag: i for i, ag in enumerate(self.possible_agents)}
            out = ({ag: obs[idx[ag]] for ag in agents},
                   {ag: float(r[idx[ag]]) for ag in agents},
                   {ag: term for ag in agents},
                   {ag: trunc for ag in agents},
                   {ag: {k: (v[idx[ag]] if np.ndim(v) == 1 and len(v) == fenv.n else v)
                         for k, v in info.items()} for ag in agents})
            if term or trunc:
                self.agents = []
            return out

        def state(self):
            """The global observation: every agent's last observation, flattened."""
            return self._stepper.last_obs.ravel()

        def render(self):
            return None

        def close(self):
            pass

    return ParallelEnv


_CLASSES = {}


def _cls(name, maker):
    if name not in _CLASSES:
        _CLASSES[name] = maker()
    return _CLASSES[name]


def make_parallel(fenv, params=None):
    return _cls("parallel", _make_parallel_class)(fenv, params)


def _make_gym_class():
    try:
        import gymnasium as gym
    except ImportError as e:  # pragma: no cover - depends on the extra
        from ..core.errors import AvError
        raise AvError("gym_env needs gymnasium: pip install 'avblocks[rl]'") from e

    class GymEnv(gym.Env):
        """A single-agent diagram as a Gymnasium ``Env`` (see :func:`avblocks.rl.gym_env`)."""

        metadata = {"render_modes": []}

        def __init__(self, fenv, params=None):
            if fenv.n != 1:
                from ..core.errors import ParameterError
                raise ParameterError("gym_env needs a single-agent diagram", param="act",
                                     expected="an Action block with 1 agent",
                                     found=f"{fenv.n} agents",
                                     hint="use parallel_env for several agents")
            self.fenv = fenv
            self.params = params
            self.observation_space = _obs_box(fenv, (fenv.obs_dim,))
            self.action_space = _act_box(fenv, (fenv.act_dim,))
            self._stepper = _Stepper(fenv)
            self.render_mode = None

        def set_param(self, path, value):
            """Set a numeric parameter for the following episodes."""
            _set_param(self, path, value)

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            if seed is not None:
                self._stepper.seed(seed)
            params = (options or {}).get("params", self.params)
            return self._stepper.reset(params)[0], {}

        def step(self, action):
            obs, r, term, trunc, info = self._stepper.step(action, self.params)
            info = {k: (v[0] if np.ndim(v) == 1 and len(v) == 1 else v)
                    for k, v in info.items()}
            return obs[0], float(r[0]), term, trunc, info

    return GymEnv


def make_gym(fenv, params=None):
    return _cls("gym", _make_gym_class)(fenv, params)


def _make_vector_class():
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode
    from gymnasium.vector.utils import batch_space

    class VectorEnv(gym.vector.VectorEnv):
        """K copies of a diagram as one Gymnasium ``VectorEnv`` (module docstring).

        Observation ``(K, N, obs_dim)`` and action ``(K, N, act_dim)`` for a
        multi-agent diagram (the team is the agent; ``(K, obs_dim)`` and
        ``(K, act_dim)`` when N = 1); reward ``(K,)`` is the mean over the
        agents, per-agent rewards are in ``infos["agent_rewards"]``.
        """

        metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

        def __init__(self, fenv, num_envs, params=None):
            self.fenv = fenv
            self.num_envs = int(num_envs)
            self.params = params
            n = fenv.n
            self._single = n == 1
            oshape = (fenv.obs_dim,) if self._single else (n, fenv.obs_dim)
            ashape = (fenv.act_dim,) if self._single else (n, fenv.act_dim)
            self.single_observation_space = _obs_box(fenv, oshape)
            self.single_action_space = _act_box(fenv, ashape)
            self.observation_space = batch_space(self.single_observation_space, self.num_envs)
            self.action_space = batch_space(self.single_action_space, self.num_envs)
            self._key = _engine.rng.key(0, _STREAM)
            self.state = None
            if fenv.backend == "jax":
                jax = _engine.jax()
                self._reset = jax.jit(jax.vmap(fenv.reset, in_axes=(0, None)))
                self._step = jax.jit(jax.vmap(fenv.step, in_axes=(0, 0, 0, None)))
            else:
                from .batched import BatchedEnv
                batch = BatchedEnv(fenv)
                self._reset, self._step = batch.reset, batch.step
            self.render_mode = None

        def set_param(self, path, value):
            """Set a numeric parameter for the following episodes (all copies)."""
            _set_param(self, path, value)

        def _keys(self, k):
            self._key, sub = _engine.rng.split(self._key, np, 2)
            return np.stack(_engine.rng.split(sub, np, k)).astype(np.uint32)

        def _shape_obs(self, obs):
            obs = np.asarray(obs)
            return obs[:, 0] if self._single else obs

        def reset(self, *, seed=None, options=None):
            if seed is not None:
                self._key = _engine.rng.key(int(seed), _STREAM)
            params = (options or {}).get("params", self.params)
            keys = self._keys(self.num_envs)
            self.state, obs = self._reset(keys, params)
            self.fenv.check(self.state)     # a search cut short is never silent
            return self._shape_obs(obs), {}

        def step(self, actions):
            fe = self.fenv
            a = np.asarray(actions, dtype=np.float32).reshape(
                self.num_envs, fe.n, fe.act_dim)
            a = np.clip(a, fe.action_low, fe.action_high)
            keys = self._keys(self.num_envs)
            self.state, obs, r, d, info = self._step(keys, self.state, a, self.params)
            self.fenv.check(self.state)
            info = {k: np.asarray(v) for k, v in info.items()}
            r = np.asarray(r)
            term = np.asarray(info["terminated"], dtype=bool)
            trunc = np.asarray(info["truncated"], dtype=bool)
            ended = term | trunc
            infos = {"agent_rewards": r, "final_obs": self._shape_obs(info.pop("final_obs")),
                     "_final_obs": ended, "agent_done": info.pop("agent_done")}
            infos.update({k: v for k, v in info.items() if k not in ("terminated", "truncated")})
            return (self._shape_obs(obs), r.mean(axis=1).astype(np.float32), term, trunc,
                    infos)

    return VectorEnv


def make_vector(fenv, num_envs, params=None):
    return _cls("vector", _make_vector_class)(fenv, num_envs, params)
