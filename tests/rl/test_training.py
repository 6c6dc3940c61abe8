"""Training, shortened: PPO and analytic policy gradients improve the return
within a few updates, and the trained weights run as a Policy block."""

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("optax")

from avblocks import rl  # noqa: E402
from avblocks.rl import apg, ppo  # noqa: E402


def test_ppo_improves_the_return_on_spread():
    env = rl.functional("spread", max_steps=25)
    cfg = ppo.Config(num_envs=16, updates=40, hidden=(32, 32), lr=1e-3)
    res = ppo.train(env, cfg, seed=0)
    r = np.asarray(res.curve["return"])
    assert r[-5:].mean() > r[:5].mean() + 0.2 * abs(r[:5].mean())
    # deterministic evaluation agrees: better than the untrained (zero-output) actor
    zero = {k: np.zeros_like(v) for k, v in res.actor.items()}
    assert ppo.evaluate(env, res.actor, 32)["return"] > ppo.evaluate(env, zero, 32)["return"]


def test_apg_improves_the_return_on_spread_and_runs_as_a_block(tmp_path):
    import avblocks as av
    from avblocks.controllers import save_policy
    from avblocks.scenarios import spread
    env = rl.functional("spread", max_steps=25)
    cfg = apg.Config(num_envs=16, updates=25, hidden=(32,), lr=3e-3, horizon=25)
    res = apg.train(env, cfg, seed=0)
    c = np.asarray(res.curve["cost"])
    assert c[-3:].mean() < 0.7 * c[:3].mean()
    ev = ppo.evaluate(env, res.actor, 32, output="tanh")
    assert np.isclose(ev["return"], -25 * np.mean(c[-1:]), rtol=0.5)
    # the same weights in the scenario's diagram, NumPy engine == the env's rollout
    path = save_policy(tmp_path / "pi.npz", res.actor, output="tanh")
    d, sim = spread.make_diagram(controller=str(path))
    a = av.simulate(d, **sim)
    b = av.simulate(d, **sim, backend="jax")
    np.testing.assert_allclose(b["fleet.position"], a["fleet.position"], atol=1e-8)
    assert float(np.asarray(a["task.reward"])[-1, 0]) > float(np.asarray(a["task.reward"])[0, 0])


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
