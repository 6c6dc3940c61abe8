"""The NumPy vector environment steps K copies as one call on stacked
arrays (avblocks.rl.batched): it equals K independent environments, with
automatic resets, copies out of step (a terminated episode), per-copy
parameters (each episode's drawn goals) and blocks that are not batched
(the shapely range sensor, the collision block), and passes Gymnasium's
vector-environment checks."""

import numpy as np
import pytest

pytest.importorskip("gymnasium")

from avblocks import rl  # noqa: E402
from avblocks.core import rng  # noqa: E402
from avblocks.rl.batched import BatchedEnv  # noqa: E402


def _compare(name, K=5, steps=70, **kw):
    fe = rl.functional(name, backend="numpy", **kw)
    be = BatchedEnv(fe)
    keys = [rng.key(i, "b") for i in range(K)]
    bs, bo = be.reset(keys)
    singles = [fe.reset(k) for k in keys]
    np.testing.assert_array_equal(bo, np.stack([s[1] for s in singles]))
    gen = np.random.default_rng(0)
    ended = 0
    for t in range(steps):
        a = gen.uniform(-1, 1, (K, fe.n, fe.act_dim))
        sk = [rng.key(1000 + t * K + c, "s") for c in range(K)]
        bs, bo, br, bd, bi = be.step(sk, bs, a)
        outs = [fe.step(sk[c], singles[c][0], a[c]) for c in range(K)]
        singles = [(o[0], o[1]) for o in outs]
        np.testing.assert_allclose(bo, np.stack([o[1] for o in outs]), rtol=0, atol=1e-12)
        np.testing.assert_allclose(br, np.stack([o[2] for o in outs]), rtol=0, atol=1e-12)
        np.testing.assert_array_equal(bd, np.stack([o[3] for o in outs]))
        for key in ("terminated", "truncated"):
            np.testing.assert_array_equal(bi[key], [bool(o[4][key]) for o in outs])
        for c in range(K):
            assert int(bs.steps[c]) == int(outs[c][0].steps)
            for i, x in enumerate(outs[c][0].X):
                for k, v in x.items():
                    np.testing.assert_allclose(np.asarray(bs.X[i][k][c], float),
                                               np.asarray(v, float), rtol=0, atol=1e-12)
        ended += int(bd[:, 0].sum())
    return be, ended


def test_batched_navigation_equals_independent_envs():
    be, ended = _compare("navigation", observe_velocity=True)
    assert ended == 5                                    # every copy reset once (60 steps)
    safe = {n for n, s in zip(be.fenv.cd.names, be.eng.safe) if s}
    assert {"task", "action", "speed"} <= safe           # batched
    assert not ({"lidar", "contact", "fleet"} & safe)    # once per copy


def test_batched_pursuit_copies_out_of_step_equal_independent_envs():
    # captures terminate episodes at different steps: copies with different
    # step counters are stepped in groups
    be, ended = _compare("pursuit", K=6, steps=90)
    assert ended >= 6


def test_batched_spread_with_step_params():
    fe = rl.functional("spread", backend="numpy", max_steps=4)
    be = BatchedEnv(fe)
    keys = [rng.key(i, "p") for i in range(3)]
    bs, _ = be.reset(keys)
    singles = [fe.reset(k)[0] for k in keys]
    a = np.full((3, fe.n, 2), 0.3)
    params = {"speed.k": 0.5}
    bs, bo, br, _, _ = be.step_env(bs, a, params)
    for c in range(3):
        _, o, r, _, _ = fe.step_env(singles[c], a[c], params)
        np.testing.assert_allclose(bo[c], o, rtol=0, atol=1e-12)
        np.testing.assert_allclose(br[c], r, rtol=0, atol=1e-12)


def test_numpy_vector_env_is_batched_and_passes_gymnasium_checks():
    from gymnasium.utils.env_checker import check_env
    from gymnasium.vector import AutoresetMode
    venv = rl.vector_env("navigation", 4, backend="numpy", max_steps=3)
    assert isinstance(venv._step.__self__, BatchedEnv)
    assert venv.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    obs, _ = venv.reset(seed=1)
    assert venv.observation_space.contains(obs)
    for _ in range(4):
        a = venv.action_space.sample()
        obs, r, te, tr, info = venv.step(a)
        assert venv.observation_space.contains(obs)
        assert r.shape == (4,) and r.dtype == np.float32
        assert te.shape == tr.shape == (4,)
    # same numbers as the compiled vector env (float32 there)
    vj = rl.vector_env("navigation", 4, backend="jax", max_steps=3)
    oj, _ = vj.reset(seed=1)
    on, _ = rl.vector_env("navigation", 4, backend="numpy", max_steps=3).reset(seed=1)
    np.testing.assert_allclose(on, oj, atol=2e-5)
    check_env(rl.gym_env("spread", agents=1), skip_render_check=True)
