"""Training, shortened: PPO and analytic policy gradients improve the return
within a few updates, and the trained weights run as a Policy block."""

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("optax")

from avblocks import rl  # noqa: E402
from avblocks.rl import apg, ppo  # noqa: E402

#: XLA programs built in this process (JAX's monitoring event for each
#: backend compile), appended by a listener registered once
_BUILT = []


def _listen(event, secs, **kw):
    if event == "/jax/core/compile/backend_compile_duration":
        _BUILT.append(secs)


jax.monitoring.register_event_duration_secs_listener(_listen)


def _programs(fn, *a, **kw):
    """``fn(*a, **kw)`` and how many XLA programs it built."""
    n = len(_BUILT)
    out = fn(*a, **kw)
    return out, len(_BUILT) - n


def test_ppo_improves_the_return_on_navigation():
    env = rl.functional("navigation", max_steps=30)
    cfg = ppo.Config(num_envs=16, updates=30, hidden=(32, 32), lr=1e-3, normalize_obs=True)
    res, built = _programs(ppo.train, env, cfg, seed=0)
    # the start (optimizer state, key, statistics), the update and the
    # action box's transfer; made op by op, the start was 300 programs
    assert built <= 3, built
    r = np.asarray(res.curve["return"])
    assert r[-5:].mean() > r[:5].mean() + 5.0          # -11 -> about 0 here
    # deterministic evaluation agrees: better than the untrained actor
    from avblocks.rl.ppo import init_params
    p0 = {k: np.asarray(v) for k, v in init_params(env, cfg, 0)["actor"].items()}
    assert ppo.evaluate(env, res.actor, 32)["return"] > ppo.evaluate(env, p0, 32)["return"] + 1


def _to_go(obs, reward, info, action, xp):
    return xp.sqrt(xp.sum(obs[:, 0:2] ** 2, -1) + 1e-9)       # distance to the goal


def test_apg_lowers_its_cost_and_runs_as_a_block(tmp_path):
    import avblocks as av
    from avblocks.controllers import save_policy
    from avblocks.scenarios import navigation
    env = rl.functional("navigation", max_steps=30)
    cfg = apg.Config(num_envs=16, updates=30, hidden=(32,), lr=3e-3, horizon=10)
    res, built = _programs(apg.train, env, cfg, seed=0, cost=_to_go)
    assert built <= 3, built            # the start, the step, the action box
    c = np.asarray(res.curve["cost"])
    assert np.isfinite(c).all() and c[-3:].mean() < 0.8 * c[:3].mean()
    # the same weights in the scenario's diagram: NumPy engine == compiled
    path = save_policy(tmp_path / "pi.npz", res.actor, output="tanh")
    d, sim = navigation.make_diagram(controller=str(path), seed=2)
    a = av.simulate(d, **sim)
    b = av.simulate(d, **sim, backend="jax")
    np.testing.assert_allclose(b["fleet.position"], a["fleet.position"], atol=1e-8)
    g = np.asarray(a["goals.y"])[0]
    p = np.asarray(a["fleet.position"])
    assert np.linalg.norm(p[-1] - g, axis=1).mean() < 0.8 * np.linalg.norm(p[0] - g,
                                                                           axis=1).mean()


def test_gradient_through_a_stopped_agent_is_finite():
    # SingleIntegrator's speed limit at zero velocity: d|v|/dv is infinite
    # at 0; the limit must not turn a zero cotangent into NaN
    import jax.numpy as jnp

    from avblocks.vehicles._common import clip_norm

    def f(v):
        return jnp.sum(clip_norm(v, jnp.array([1.0, 1.0]), jnp) * 0.0 + clip_norm(v, 1.0, jnp))

    g = jax.grad(f)(jnp.zeros((2, 2)))
    assert np.isfinite(np.asarray(g)).all()
    np.testing.assert_allclose(np.asarray(g), 1.0)          # identity below the limit
    v = jnp.array([[3.0, 4.0]])
    np.testing.assert_allclose(np.asarray(clip_norm(v, jnp.array([1.0]), jnp)), [[0.6, 0.8]],
                               rtol=1e-6)


def test_observation_standardization_folds_into_the_first_layer():
    """Running statistics merge like the statistics of the concatenated
    batches, and the folded weights on raw observations give what the
    trained network gives on standardized ones (so the saved Policy needs
    no extra block)."""
    import jax.numpy as jnp

    from avblocks.controllers.policy import mlp, mlp_init
    rng = np.random.default_rng(0)
    a = rng.normal(2.0, 3.0, size=(50, 5))
    b = rng.normal(-1.0, 0.5, size=(70, 5))
    nrm = {"mean": jnp.asarray(a.mean(0)), "var": jnp.asarray(a.var(0)),
           "count": jnp.asarray(50.0)}
    m = ppo._merge_stats(nrm, jnp.asarray(b), jnp)
    both = np.concatenate([a, b])
    np.testing.assert_allclose(np.asarray(m["mean"]), both.mean(0), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(np.asarray(m["var"]), both.var(0), rtol=1e-4)
    assert float(m["count"]) == 120.0
    w = mlp_init([5, 8, 2], seed=3, gain_last=1.0)
    st = {"mean": both.mean(0), "var": both.var(0)}
    z = (both - st["mean"]) / np.sqrt(st["var"] + 1e-8)
    np.testing.assert_allclose(mlp(ppo.fold_stats(w, st), both), mlp(w, z), atol=1e-10)
    # a critic with one more input (the time feature) keeps that row
    wc = mlp_init([6, 8, 1], seed=4, gain_last=1.0)
    x6 = np.concatenate([both, rng.uniform(size=(120, 1))], axis=1)
    z6 = np.concatenate([z, x6[:, 5:]], axis=1)
    np.testing.assert_allclose(mlp(ppo.fold_stats(wc, st, 5), x6), mlp(wc, z6), atol=1e-10)
