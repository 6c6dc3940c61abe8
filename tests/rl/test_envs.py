"""avblocks.rl environments: API conformance (PettingZoo, Gymnasium) and
the numbers a step returns against the task's equations computed here."""

import numpy as np
import pytest

pytest.importorskip("pettingzoo")
pytest.importorskip("gymnasium")
jax = pytest.importorskip("jax")

from avblocks import rl  # noqa: E402


def _spread_reward(p, lm, radius=0.1, collision=1.0):
    dl = np.linalg.norm(p[:, None] - lm[None], axis=-1)
    near = dl.min(axis=0)
    dd = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.diag(np.full(len(p), np.inf))
    return -near.sum() - collision * (dd < 2 * radius).sum(axis=1)


def test_parallel_api_and_seed():
    from pettingzoo.test import parallel_api_test, parallel_seed_test
    parallel_api_test(rl.parallel_env("spread"), num_cycles=60)
    parallel_seed_test(lambda: rl.parallel_env("spread"))


def test_parallel_api_on_jax_engine():
    from pettingzoo.test import parallel_api_test
    parallel_api_test(rl.parallel_env("spread", backend="jax", max_steps=20), num_cycles=30)


@pytest.mark.parametrize("backend", ["numpy", "jax"])
def test_step_moves_agents_and_rewards_as_the_equations_say(backend):
    env = rl.functional("spread", backend=backend)
    p0 = np.array([[-0.5, 0.0], [0.5, 0.0], [0.0, 0.8]])
    lm = np.array([[0.9, 0.9], [-0.9, -0.9], [0.0, -0.5]])
    params = {"landmarks.value": lm}
    state, obs = env.reset(np.array([1, 2], np.uint32), params)
    # place the agents exactly (a state override through the state pytree)
    X = list(state.X)
    i = env.cd.index("fleet")
    X[i] = {**X[i], "position": env.xp.asarray(p0, dtype=X[i]["position"].dtype)}
    lm_t = env.xp.asarray(lm, dtype=state.theta["landmarks.value"].dtype)
    state = state._replace(X=X, theta={**state.theta, "landmarks.value": lm_t})
    a = np.array([[1.0, 0.0], [0.0, -1.0], [0.5, 0.5]], np.float32)
    state, obs, r, d, info = env.step_env(state, a)
    p1 = p0 + 1.0 * a * 0.1                     # speed 1 m/s, one 0.1 s step
    tol = 1e-5 if backend == "jax" else 1e-12
    np.testing.assert_allclose(np.asarray(obs)[:, :2], p1, atol=tol)
    np.testing.assert_allclose(np.asarray(obs)[:, 2:4], lm[0] - p1, atol=tol)
    np.testing.assert_allclose(np.asarray(r), _spread_reward(p1, lm), atol=10 * tol)
    assert not np.asarray(d).any()


def test_episode_truncates_at_max_steps_and_autoresets():
    env = rl.functional("spread", max_steps=3)
    step = jax.jit(env.step)
    state, obs = env.reset(np.array([5, 6], np.uint32))
    dones = []
    for k in range(7):
        state, obs2, r, d, info = step(np.array([k, 1], np.uint32), state,
                                       np.zeros((3, 2), np.float32))
        dones.append(bool(d[0]))
        if d[0]:
            assert int(state.steps) == 0                     # a new episode
            assert not np.allclose(np.asarray(info["final_obs"]), np.asarray(obs2))
    assert dones == [False, False, True, False, False, True, False]


def test_gym_env_passes_check_env():
    from gymnasium.utils.env_checker import check_env
    env = rl.gym_env("spread", agents=1)
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=3)
    assert obs.shape == (4,) and env.action_space.shape == (2,)


@pytest.mark.parametrize("backend", ["jax", "numpy"])
def test_vector_env_batches_copies(backend):
    from gymnasium.vector import AutoresetMode
    venv = rl.vector_env("spread", 4, backend=backend, max_steps=2)
    assert venv.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    obs, _ = venv.reset(seed=0)
    assert obs.shape == (4, 3, 12)
    assert len({tuple(np.round(o[:, :2].ravel(), 6)) for o in obs}) == 4   # independent copies
    a = np.zeros((4, 3, 2), np.float32)
    o1, r1, te, tr, info = venv.step(a)
    # the team reward is the mean of the agents' rewards, each from the equation
    for e in range(4):
        p = o1[e, :, :2].astype(float)
        lm = p[0] + o1[e, 0, 2:8].reshape(3, 2)
        np.testing.assert_allclose(info["agent_rewards"][e], _spread_reward(p, lm), atol=1e-4)
        assert np.isclose(r1[e], info["agent_rewards"][e].mean(), atol=1e-5)
    o2, r2, te, tr, info = venv.step(a)
    assert tr.all() and not te.any() and info["_final_obs"].all()
    np.testing.assert_allclose(info["final_obs"], o1, atol=1e-6)   # zero action: no motion
    assert not np.allclose(o2, o1)                                 # reset to new episodes
    venv2 = rl.vector_env("spread", 4, backend=backend, max_steps=2)
    np.testing.assert_array_equal(venv2.reset(seed=0)[0], obs)     # seeded


def test_functional_rollout_jits_and_vmaps():
    env = rl.functional("spread", max_steps=10)

    def policy(params, obs, key):
        return -params * obs[:, :2]                  # toward the origin

    roll = jax.jit(jax.vmap(lambda k: env.rollout(k, policy, 10, policy_params=1.0)))
    keys = jax.random.split(jax.random.PRNGKey(0), 8)
    obs, act, rew, done = roll(keys)
    assert obs.shape == (8, 10, 3, 12) and rew.shape == (8, 10, 3)
    assert np.asarray(done)[:, -1].all() and not np.asarray(done)[:, :-1].any()
    # |p| shrinks by (1 - dt) per step under u = -p (RK4 of dp/dt = -p with held u)
    p = np.asarray(obs)[:, :, :, :2]
    np.testing.assert_allclose(p[:, 1], p[:, 0] * 0.9, atol=1e-5)


def test_params_set_for_an_episode():
    env = rl.parallel_env("spread", params={"speed.k": 0.5})
    obs, _ = env.reset(seed=1)
    o, *_ = env.step({a: np.array([1.0, 0.0], np.float32) for a in env.agents})
    for a in env.possible_agents:
        np.testing.assert_allclose(o[a][:2] - obs[a][:2], [0.05, 0.0], atol=1e-6)


def test_wrong_port_is_named():
    from avblocks.core.errors import AvError
    with pytest.raises(AvError, match="nosuch"):
        rl.parallel_env("spread", reward="task.nosuch")


def test_set_param_applies_from_the_next_episode_and_is_checked():
    from avblocks.core.errors import ParameterError
    env = rl.parallel_env("spread")
    env.reset(seed=1)
    env.set_param("speed.k", 0.25)
    obs, _ = env.reset(seed=1)
    o, *_ = env.step({a: np.array([0.0, 1.0], np.float32) for a in env.agents})
    np.testing.assert_allclose(o["agent_1"][:2] - obs["agent_1"][:2], [0.0, 0.025], atol=1e-6)
    with pytest.raises(ParameterError):
        env.set_param("task.radius", -1.0)               # below its bound


def test_step_params_keep_the_episode_draws():
    # parameters passed at every step change only what they name: the
    # landmarks drawn at reset stay
    env = rl.parallel_env("spread", params={"speed.k": 0.5})
    obs, _ = env.reset(seed=4)
    lm0 = obs["agent_0"][2:8] + np.tile(obs["agent_0"][:2], 3)
    for _ in range(3):
        o, *_ = env.step({a: np.array([0.3, -0.2], np.float32) for a in env.agents})
    lm1 = o["agent_0"][2:8] + np.tile(o["agent_0"][:2], 3)
    np.testing.assert_allclose(lm1, lm0, atol=1e-6)
    marks = env.fenv.params["landmarks.value"]
    assert not np.allclose(lm0.reshape(3, 2), marks, atol=1e-3)     # drawn, not defaults
