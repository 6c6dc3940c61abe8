"""Analytic policy gradients: backpropagation through the whole run.

The episode is the compiled engine's traced step (the same
``TracedEngine`` a compiled run scans), so ``jax.grad`` of a cost summed
over an episode with respect to the policy's weights flows through the
vehicles' dynamics, the sensors and the task block: the policy is trained
by gradient descent on the simulated outcome itself, as Brax's APG does
(Freeman et al. 2021, "Brax - a differentiable physics engine for large
scale rigid body simulation"; Xu et al. 2022, "Accelerated policy learning
with parallel differentiable simulation" for the truncated form).

The policy is deterministic: ``a = tanh(mlp(w, obs))`` scaled to the
action box (the deployed :class:`~avblocks.controllers.Policy` uses
``output="tanh"``). The cost is ``cost(obs, reward, info, action, xp) ->
(N,)`` per step (default ``-reward``); indicator terms (a collision flag)
have zero gradient, so a task learned this way needs a smooth cost (see
examples/09_apg_navigation.py). Long horizons are cut into windows of
``horizon`` steps whose gradients do not flow into the previous window
(``stop_gradient`` on the state), which keeps the gradient bounded.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..controllers.policy import mlp, mlp_init
from . import _engine


@dataclass(frozen=True)
class Config:
    num_envs: int = 64
    updates: int = 200
    hidden: tuple = (64, 64)
    lr: float = 1e-3
    horizon: int = 20
    max_grad_norm: float = 1.0
    activation: str = "tanh"


@dataclass
class Result:
    """Weights of the trained actor (NumPy), learning curve (per update:
    ``cost``, ``return`` per agent, ``success`` at the episode's end,
    ``env_steps``, ``wall_s``), config."""

    actor: dict
    curve: dict = field(default_factory=dict)
    config: Config = None


def _neg_reward(obs, reward, info, action, xp):
    return -reward


def episode_loss_fn(env, cfg, cost=None):
    """``loss(w, key) -> (mean cost, (return, success))`` of one episode."""
    jax = _engine.jax()
    jnp = jax.numpy
    cost = cost or _neg_reward
    lo, hi = jnp.asarray(env.action_low), jnp.asarray(env.action_high)
    T = env.max_steps
    windows = -(-T // cfg.horizon)

    def act(w, obs):
        return lo + (jnp.tanh(mlp(w, obs, jnp, cfg.activation)) + 1.0) * 0.5 * (hi - lo)

    def episode_loss(w, key):
        state, obs = env.reset(key)

        def body(c, _):
            state, obs = c
            a = act(w, obs)
            state, obs2, r, d, info = env.step_env(state, a)
            succ = jnp.broadcast_to(info.get("success", jnp.zeros(env.n, bool)), (env.n,))
            return (state, obs2), (cost(obs2, r, info, a, jnp), r, succ)

        total, ret, succ = 0.0, 0.0, None
        c = (state, obs)
        for k in range(windows):
            n = min(cfg.horizon, T - k * cfg.horizon)
            c = jax.lax.stop_gradient(c)
            c, (cs, rs, ss) = jax.lax.scan(body, c, None, length=n)
            total = total + jnp.sum(cs)
            ret = ret + jnp.sum(rs, axis=0)
            succ = ss[-1]
        return total / (T * env.n), (jnp.mean(ret), jnp.mean(succ.astype(jnp.float32)))

    return episode_loss


def make_step(env, cfg, opt, cost=None):
    """The jitted ``update(carry) -> (carry, metrics)``."""
    jax = _engine.jax()
    jnp = jax.numpy
    E = cfg.num_envs
    episode_loss = episode_loss_fn(env, cfg, cost)

    def loss(w, key):
        vals, (ret, succ) = jax.vmap(episode_loss, in_axes=(None, 0))(
            w, jax.random.split(key, E))
        return jnp.mean(vals), (jnp.mean(ret), jnp.mean(succ))

    vg = jax.value_and_grad(loss, has_aux=True)

    def update(carry):
        w, opt_state, key = carry
        key, k = jax.random.split(key)
        (val, (ret, succ)), g = vg(w, k)
        upd, opt_state = opt.update(g, opt_state, w)
        w = jax.tree_util.tree_map(lambda a, u: a + u, w, upd)
        return (w, opt_state, key), {"cost": val, "return": ret, "success": succ}

    return jax.jit(update)


def train(env, cfg=Config(), seed=0, *, cost=None, time_budget_s=None, callback=None):
    """Train a deterministic tanh-MLP policy on ``env`` (JAX
    :class:`~avblocks.rl.FunctionalEnv`) by gradient through the episode."""
    import optax
    jax = _engine.jax()
    t0 = time.perf_counter()
    # transferred, not made by jnp ops; the optimizer state and the key made
    # by one compiled program (op by op, each op of each shape was compiled)
    w = {k: _engine.float32_on_device(v) for k, v in
         mlp_init([env.obs_dim, *cfg.hidden, env.act_dim], seed=seed, gain_last=0.1).items()}
    opt = optax.chain(optax.clip_by_global_norm(cfg.max_grad_norm), optax.adam(cfg.lr))
    carry = (w, *jax.jit(lambda w: (opt.init(w), jax.random.PRNGKey(seed)))(w))
    update = make_step(env, cfg, opt, cost)
    curve = {"cost": [], "return": [], "success": [], "env_steps": [], "wall_s": []}
    for u in range(cfg.updates):
        carry, m = update(carry)
        m = {k: float(v) for k, v in m.items()}
        for k in ("cost", "return", "success"):
            curve[k].append(m[k])
        curve["env_steps"].append((u + 1) * cfg.num_envs * env.max_steps)
        curve["wall_s"].append(time.perf_counter() - t0)
        if callback is not None:
            callback(u, m)
        if time_budget_s is not None and curve["wall_s"][-1] > time_budget_s:
            break
    return Result({k: np.asarray(v) for k, v in carry[0].items()}, curve, cfg)
