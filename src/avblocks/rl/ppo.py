"""A short PPO in JAX + optax over the functional form, jitted end to end.

Independent PPO with parameter sharing (one actor and one critic for every
agent, each agent's transition a sample): the usual choice for homogeneous
teams (IPPO; de Witt et al. 2020, "Is independent learning all you need in
the StarCraft multi-agent challenge?"). Clipped surrogate objective and
generalized advantage estimation as in Schulman et al. 2017, "Proximal
policy optimization algorithms", and Schulman et al. 2016, "High-dimensional
continuous control using generalized advantage estimation".

One update = ``num_envs`` episodes run in lockstep from fresh resets
(``FunctionalEnv.reset`` and ``step_env`` vmapped over the copies, one
``lax.scan`` over the episode), then ``epochs`` passes of ``minibatches``
Adam steps. The learning rate decays linearly to zero over the updates or
the wall-clock budget, whichever ends first (set before each update, so a
loaded machine still ends the schedule within the budget). Options: the
gradient norm clipped per network instead of jointly (``clip_separately``),
the critic given the episode's elapsed fraction (``time_feature``; the
actor never sees it), a reward scale for the losses, and observation
standardization (``normalize_obs``: running mean and variance of every
observation component, merged after each update and used by both networks;
the returned weights have it folded into their first layer, so the saved
:class:`~avblocks.controllers.Policy` reads raw observations). Transitions
after an episode terminated are masked out. The
policy is a Gaussian around an MLP mean (state-independent log std); the
deployed :class:`~avblocks.controllers.Policy` uses the mean, clipped to the
action box (``output="clip"``).

>>> from avblocks import rl
>>> from avblocks.rl import ppo
>>> env = rl.functional("spread", max_steps=5)
>>> out = ppo.train(env, ppo.Config(num_envs=4, updates=2, hidden=(16,)), seed=0)
>>> len(out.curve["return"])
2
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..controllers.policy import mlp, mlp_init
from . import _engine


@dataclass(frozen=True)
class Config:
    """PPO settings (defaults: the navigation example's)."""

    num_envs: int = 64
    updates: int = 200
    epochs: int = 4
    minibatches: int = 4
    hidden: tuple = (64, 64)
    lr: float = 3e-4
    gamma: float = 0.99
    lam: float = 0.95
    clip: float = 0.2
    vf_coef: float = 0.5
    ent_coef: float = 0.0
    max_grad_norm: float = 0.5
    log_std0: float = -0.5
    activation: str = "tanh"
    anneal: bool = True        # learning rate linearly to 0 over ``updates`` (or the
    #                            time budget, whichever ends first)
    clip_separately: bool = False  # max_grad_norm per network (actor, critic)
    reward_scale: float = 1.0  # rewards times this in the losses (not in the curve)
    time_feature: bool = False  # the critic also sees the episode's elapsed fraction
    normalize_obs: bool = False  # standardize observations by running mean/var
    #                              (folded into the first layer of the result)


@dataclass
class Result:
    """What :func:`train` returns: the actor's weights (NumPy, ready for
    :class:`~avblocks.controllers.Policy`), the critic's, the learning
    curve (per update: mean episode ``return`` per agent, ``success``
    fraction at the episode's end if the task reports ``success``,
    ``env_steps`` so far, ``wall_s``) and the config."""

    actor: dict
    critic: dict
    log_std: np.ndarray
    curve: dict = field(default_factory=dict)
    config: Config = None


def _to_np(tree):
    return {k: np.asarray(v) for k, v in tree.items()}


def make_update(env, cfg, opt):
    """The jitted ``update(carry) -> (carry, metrics)`` for ``env``."""
    jax = _engine.jax()
    jnp = jax.numpy
    E, N, T = cfg.num_envs, env.n, env.max_steps
    lo = jnp.asarray(env.action_low)
    hi = jnp.asarray(env.action_high)
    reset = jax.vmap(env.reset, in_axes=(0, None))
    step = jax.vmap(env.step_env, in_axes=(0, 0, None))
    act = cfg.activation

    def policy(p, obs, nrm):
        return mlp(p["actor"], _standardize(obs, nrm, jnp), jnp, act), p["log_std"]

    def value(p, obs, tf, nrm):
        # a fixed horizon: what is left to earn depends on the time left, which
        # the agents' observation does not say (Pardo et al. 2018, "Time limits
        # in reinforcement learning"); the critic alone sees it (the actor, the
        # deployed Policy, does not)
        obs = _standardize(obs, nrm, jnp)
        x = jnp.concatenate([obs, tf], axis=-1) if cfg.time_feature else obs
        return mlp(p["critic"], x, jnp, act)[..., 0]

    def logprob(mean, log_std, a):
        z = (a - mean) / jnp.exp(log_std)
        return jnp.sum(-0.5 * z * z - log_std - 0.5 * jnp.log(2 * jnp.pi), axis=-1)

    def rollout(p, key, nrm):
        k0, k1 = jax.random.split(key)
        state, obs = reset(jax.random.split(k0, E), None)

        def body(carry, k):
            state, obs, alive = carry
            mean, log_std = policy(p, obs, nrm)
            a = mean + jnp.exp(log_std) * jax.random.normal(k, mean.shape)
            lp = logprob(mean, log_std, a)
            tf = jnp.broadcast_to((state.steps / T).astype(jnp.float32)[:, None, None],
                                  (E, N, 1))
            v = value(p, obs, tf, nrm)
            state, obs2, r, d, info = step(state, jnp.clip(a, lo, hi), None)
            term = info["terminated"][:, None] & alive
            succ = info.get("success", jnp.zeros((E, N), bool)).reshape(E, -1)
            out = dict(obs=obs, tf=tf, a=a, lp=lp, v=v, r=r * alive, alive=alive,
                       term=jnp.broadcast_to(term, (E, N)),
                       succ=jnp.broadcast_to(succ, (E, N)))
            return (state, obs2, alive & ~term), out

        alive0 = jnp.ones((E, 1), bool)
        (state, obs, alive), tr = jax.lax.scan(body, (state, obs, alive0),
                                               jax.random.split(k1, T))
        tr["alive"] = jnp.broadcast_to(tr["alive"], tr["r"].shape)
        return tr, value(p, obs, jnp.ones(obs.shape[:-1] + (1,), jnp.float32), nrm)

    def gae(tr, last_v):
        # episodes end at T (truncation treated as the end: fixed horizon)
        def back(carry, x):
            adv, v_next = carry
            r, v, term, alive = x
            nonterm = 1.0 - term.astype(jnp.float32)
            delta = r + cfg.gamma * v_next * nonterm - v
            adv = delta + cfg.gamma * cfg.lam * nonterm * adv
            adv = adv * alive
            return (adv, v), adv

        zeros = jnp.zeros_like(last_v)
        _, adv = jax.lax.scan(back, (zeros, zeros),
                              (tr["r"], tr["v"], tr["term"], tr["alive"]), reverse=True)
        return adv, adv + tr["v"]

    def loss(p, b, nrm):
        mean, log_std = policy(p, b["obs"], nrm)
        lp = logprob(mean, log_std, b["a"])
        ratio = jnp.exp(lp - b["lp"])
        adv = b["adv"]
        w = b["alive"].astype(jnp.float32)
        wsum = jnp.maximum(jnp.sum(w), 1.0)
        mu = jnp.sum(adv * w) / wsum
        sd = jnp.sqrt(jnp.sum(w * (adv - mu) ** 2) / wsum)
        adv = (adv - mu) / (sd + 1e-8)
        pg = -jnp.minimum(ratio * adv, jnp.clip(ratio, 1 - cfg.clip, 1 + cfg.clip) * adv)
        v = value(p, b["obs"], b["tf"], nrm)
        vl = 0.5 * (v - b["ret"]) ** 2
        ent = jnp.sum(log_std + 0.5 * jnp.log(2 * jnp.pi * jnp.e))
        total = jnp.sum((pg + cfg.vf_coef * vl) * w) / wsum - cfg.ent_coef * ent
        return total

    grad = jax.grad(loss)

    def update(carry):
        p, opt_state, key, nrm = carry
        key, kr, ks = jax.random.split(key, 3)
        tr, last_v = rollout(p, kr, nrm)
        adv, ret = gae({**tr, "r": tr["r"] * cfg.reward_scale}, last_v)
        flat = {k: tr[k].reshape((T * E * N,) + tr[k].shape[3:])
                for k in ("obs", "tf", "a", "lp", "alive")}
        flat["adv"] = adv.reshape(-1)
        flat["ret"] = ret.reshape(-1)
        size = T * E * N
        mb = size // cfg.minibatches

        def epoch(c, k):
            p, opt_state = c
            perm = jax.random.permutation(k, size)[: mb * cfg.minibatches]
            batches = {kk: v[perm].reshape((cfg.minibatches, mb) + v.shape[1:])
                       for kk, v in flat.items()}

            def mini(c, b):
                p, opt_state = c
                g = grad(p, b, nrm)
                if cfg.clip_separately:
                    # the critic's squared error would otherwise dominate one
                    # global norm and scale the actor's step down with it
                    g = {"actor": _clip(g["actor"], cfg.max_grad_norm),
                         "log_std": g["log_std"],
                         "critic": _clip(g["critic"], cfg.max_grad_norm)}
                upd, opt_state = opt.update(g, opt_state, p)
                p = jax.tree_util.tree_map(lambda a, u: a + u, p, upd)
                return (p, opt_state), None

            c, _ = jax.lax.scan(mini, (p, opt_state), batches)
            return c, None

        (p, opt_state), _ = jax.lax.scan(epoch, (p, opt_state),
                                         jax.random.split(ks, cfg.epochs))
        alive = tr["alive"].astype(jnp.float32)
        ep_ret = jnp.sum(tr["r"], axis=0).mean()
        # success: at the last step alive, or at termination
        last = tr["succ"][-1]
        metrics = {"return": ep_ret, "success": jnp.mean(last.astype(jnp.float32)),
                   "alive": alive.mean()}
        if cfg.normalize_obs:
            nrm = _merge_stats(nrm, flat["obs"], jnp)
        return (p, opt_state, key, nrm), metrics

    return jax.jit(update)


def _standardize(obs, nrm, xp):
    if nrm is None:
        return obs
    return (obs - nrm["mean"]) / xp.sqrt(nrm["var"] + 1e-8)


def _merge_stats(nrm, x, xp):
    """Running mean/variance (count-weighted merge of the batch ``x``;
    Chan et al. 1979, "Updating formulae and a pairwise algorithm for
    computing sample variances")."""
    n = xp.asarray(x.shape[0], xp.float32)
    m, v = xp.mean(x, axis=0), xp.var(x, axis=0)
    c = nrm["count"]
    tot = c + n
    delta = m - nrm["mean"]
    mean = nrm["mean"] + delta * n / tot
    var = (nrm["var"] * c + v * n + delta * delta * c * n / tot) / tot
    return {"mean": mean, "var": var, "count": tot}


def init_stats(env, num_envs, seed=0):
    """Observation statistics of ``num_envs`` fresh resets (the first
    update's standardization)."""
    jax = _engine.jax()
    jnp = jax.numpy
    keys = jax.random.split(jax.random.PRNGKey(seed + 7), num_envs)
    _, obs = jax.vmap(env.reset, in_axes=(0, None))(keys, None)
    x = obs.reshape(-1, obs.shape[-1])
    return {"mean": jnp.mean(x, 0), "var": jnp.var(x, 0),
            "count": jnp.asarray(x.shape[0], jnp.float32)}


def fold_stats(w, nrm, rows=None):
    """MLP weights ``w`` that take raw observations: the standardization
    ``(obs - mean) / std`` folded into the first layer (``rows``: how many
    input rows are observations; the rest, e.g. a time feature, unchanged)."""
    w = {k: np.asarray(v, np.float64) for k, v in w.items()}
    if nrm is None:
        return w
    mean = np.asarray(nrm["mean"], np.float64)
    std = np.sqrt(np.asarray(nrm["var"], np.float64) + 1e-8)
    k = mean.size if rows is None else rows
    w0 = w["w0"].copy()
    w0[:k] = w0[:k] / std[:, None]
    w["b0"] = w["b0"] - (mean / std) @ w["w0"][:k]
    w["w0"] = w0
    return w


def _set_lr(carry, lr, plain):
    p, opt_state, key, nrm = carry
    inner = opt_state if plain else opt_state[1]
    hp = dict(inner.hyperparams)
    hp["learning_rate"] = np.asarray(lr, np.float32)
    inner = inner._replace(hyperparams=hp)
    opt_state = inner if plain else (opt_state[0], inner)
    return p, opt_state, key, nrm


def _clip(tree, max_norm):
    """``tree`` scaled to global norm <= ``max_norm`` (optax's rule)."""
    jax = _engine.jax()
    jnp = jax.numpy
    leaves = jax.tree_util.tree_leaves(tree)
    norm = jnp.sqrt(sum(jnp.sum(x * x) for x in leaves))
    scale = jnp.minimum(1.0, max_norm / jnp.maximum(norm, 1e-12))
    return jax.tree_util.tree_map(lambda x: x * scale, tree)


def init_params(env, cfg, seed=0):
    """Initial actor, critic and log std (float32 device arrays)."""
    sizes = [env.obs_dim, *cfg.hidden]
    actor = mlp_init(sizes + [env.act_dim], seed=seed, gain_last=0.01)
    csizes = [env.obs_dim + (1 if cfg.time_feature else 0), *cfg.hidden, 1]
    critic = mlp_init(csizes, seed=seed + 1, gain_last=1.0)
    f32 = _engine.float32_on_device
    return {"actor": {k: f32(v) for k, v in actor.items()},
            "critic": {k: f32(v) for k, v in critic.items()},
            "log_std": f32(np.full((env.act_dim,), cfg.log_std0))}


def _start(env, cfg, opt, seed):
    """The first carry ``(params, optimizer state, key, statistics)``. The
    optimizer state, the key and the first statistics come from one
    compiled program: made op by op, they were some 300 one-op programs,
    each compiled (about 6 of the 11 s of a short training)."""
    jax = _engine.jax()
    p = init_params(env, cfg, seed)

    def rest(p):
        nrm = init_stats(env, cfg.num_envs, seed) if cfg.normalize_obs else None
        return opt.init(p), jax.random.PRNGKey(seed), nrm

    state, key, nrm = jax.jit(rest)(p)
    return p, state, key, nrm


def train(env, cfg=Config(), seed=0, *, time_budget_s=None, callback=None):
    """Train on ``env`` (a JAX :class:`~avblocks.rl.FunctionalEnv`) for
    ``cfg.updates`` updates or within ``time_budget_s`` (wall clock, the
    compile included: training stops when one more update as long as the
    last would end past it); returns :class:`Result`."""
    import optax
    t0 = time.perf_counter()
    # the learning rate is set before each update (annealed over the updates
    # or the wall-clock budget, whichever runs out first: on a loaded
    # machine the schedule still ends at zero within the budget)
    adam = optax.inject_hyperparams(optax.adam)(learning_rate=cfg.lr, eps=1e-5)
    opt = adam if cfg.clip_separately else optax.chain(
        optax.clip_by_global_norm(cfg.max_grad_norm), adam)
    carry = _start(env, cfg, opt, seed)
    update = make_update(env, cfg, opt)
    curve = {"return": [], "success": [], "env_steps": [], "wall_s": []}
    per = cfg.num_envs * env.max_steps
    for u in range(cfg.updates):
        if cfg.anneal:
            frac = 1.0 - u / cfg.updates
            if time_budget_s is not None:
                frac = min(frac, 1.0 - (time.perf_counter() - t0) / time_budget_s)
            carry = _set_lr(carry, cfg.lr * max(frac, 0.0), cfg.clip_separately)
        carry, m = update(carry)
        m = {k: float(v) for k, v in m.items()}
        curve["return"].append(m["return"])
        curve["success"].append(m["success"])
        curve["env_steps"].append((u + 1) * per)
        curve["wall_s"].append(time.perf_counter() - t0)
        if callback is not None:
            callback(u, m)
        # stop when the next update, as long as the last one, would end
        # past the budget (the budget is kept, not overrun by one update)
        now = curve["wall_s"][-1]
        last = now - (curve["wall_s"][-2] if u else 0.0)
        if time_budget_s is not None and now + last > time_budget_s:
            break
    p, nrm = carry[0], carry[3]
    return Result(fold_stats(_to_np(p["actor"]), nrm),
                  fold_stats(_to_np(p["critic"]), nrm, env.obs_dim),
                  np.asarray(p["log_std"]), curve, cfg)


def evaluate(env, actor, episodes=100, seed=1234, activation="tanh", output="clip"):
    """Deterministic (mean action) evaluation over ``episodes`` episodes in
    one vmapped, jitted rollout: ``{"success": fraction of agents with
    success at the end, "return": mean return per agent, "collided":
    fraction of agents that collided (if the task reports it)}``.
    ``output``: how the MLP's output becomes the action, as
    :class:`~avblocks.controllers.Policy` (``"clip"`` for PPO's Gaussian
    mean, ``"tanh"`` for :mod:`avblocks.rl.apg`)."""
    jax = _engine.jax()
    jnp = jax.numpy
    lo, hi = jnp.asarray(env.action_low), jnp.asarray(env.action_high)
    w = {k: jnp.asarray(v, jnp.float32) for k, v in actor.items()}

    def episode(key):
        state, obs = env.reset(key)

        def body(c, _):
            state, obs, hit = c
            y = mlp(w, obs, jnp, activation)
            if output == "tanh":
                a = lo + (jnp.tanh(y) + 1.0) * 0.5 * (hi - lo)
            else:
                a = jnp.clip(y, lo, hi)
            state, obs, r, d, info = env.step_env(state, a)
            col = info.get("collision", jnp.zeros(env.n, bool))
            return (state, obs, hit | col), (r, info.get("success", jnp.zeros(env.n, bool)))

        (state, obs, hit), (r, s) = jax.lax.scan(body, (state, obs, jnp.zeros(env.n, bool)),
                                                 None, length=env.max_steps)
        return r.sum(0), s[-1], hit

    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)
    r, s, hit = jax.jit(jax.vmap(episode))(keys)
    return {"success": float(np.mean(s)), "return": float(np.mean(r)),
            "collided": float(np.mean(hit))}
