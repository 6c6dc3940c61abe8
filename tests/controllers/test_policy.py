"""controllers.Policy: the MLP against a hand computation, both engines,
check_block, .npz round trip, and a trained-policy diagram run."""

import numpy as np
import pytest

import avblocks as av
from avblocks.controllers import Policy, mlp, mlp_init


def _by_hand(p, x):
    h = np.tanh(x @ p["w0"] + p["b0"])
    h = np.tanh(h @ p["w1"] + p["b1"])
    return h @ p["w2"] + p["b2"]


def test_mlp_matches_the_equations():
    p = mlp_init([5, 8, 8, 2], seed=3, gain_last=1.0)
    p = {k: v + 0.1 for k, v in p.items()}
    x = np.random.default_rng(0).normal(size=(7, 5))
    np.testing.assert_allclose(mlp(p, x, np), _by_hand(p, x), rtol=1e-12)
    blk = Policy(p, n=7, output="tanh", low=[-2.0, 0.0], high=[2.0, 1.0])
    y = blk.output(0.0, {}, {"obs": x}, np)["cmd"]
    s = np.tanh(_by_hand(p, x))
    np.testing.assert_allclose(y, np.array([-2.0, 0.0]) + (s + 1) / 2 * np.array([4.0, 1.0]),
                               rtol=1e-12)


def test_check_block_passes():
    p = mlp_init([4, 16, 2], seed=1)
    av.core.check_block(lambda n: Policy(p, n=n))


def test_same_output_on_numpy_and_compiled_engines():
    pytest.importorskip("jax")
    p = mlp_init([2, 16, 2], seed=2, gain_last=1.0)
    n = 5
    d = av.Diagram()
    fleet = d.add(av.vehicles.SingleIntegrator(np.random.default_rng(1).normal(size=(n, 2))),
                  name="fleet")
    pol = d.add(Policy(p, output="tanh"), name="policy")
    d.connect(fleet.position, pol.obs)
    d.connect(pol.cmd, fleet.velocity)
    a = av.simulate(d, 2.0, dt=0.05, log=[fleet.position, pol.cmd])
    b = av.simulate(d, 2.0, dt=0.05, log=[fleet.position, pol.cmd], backend="jax")
    np.testing.assert_allclose(b["fleet.position"], a["fleet.position"], atol=1e-9)
    np.testing.assert_allclose(b["policy.cmd"], a["policy.cmd"], atol=1e-9)
    # weights are ordinary numeric parameters: zero weights stop everyone
    z = {f"policy.{k}": np.zeros_like(v) for k, v in p.items()}
    c = av.simulate(d, 1.0, dt=0.05, log=[fleet.position], params=z)
    np.testing.assert_allclose(c["fleet.position"][-1], c["fleet.position"][0])


def test_npz_round_trip(tmp_path):
    p = mlp_init([3, 8, 2], seed=4, gain_last=1.0)
    blk = Policy(p, activation="relu", output="tanh", low=-0.5, high=0.5)
    path = blk.save(tmp_path / "pi.npz")
    back = Policy.load(path, n=4)
    x = np.random.default_rng(5).normal(size=(4, 3))
    ref = Policy(p, activation="relu", output="tanh", low=-0.5, high=0.5, n=4)
    np.testing.assert_array_equal(back.output(0, {}, {"obs": x}, np)["cmd"],
                                  ref.output(0, {}, {"obs": x}, np)["cmd"])
    assert back.activation == "relu" and back.squash_ == "tanh"


def test_wrong_observation_size_is_named():
    p = mlp_init([3, 8, 2])
    d = av.Diagram()
    fleet = d.add(av.vehicles.SingleIntegrator(np.zeros((2, 2))), name="fleet")
    pol = d.add(Policy(p), name="policy")
    d.connect(fleet.position, pol.obs)
    d.connect(pol.cmd, fleet.velocity)
    with pytest.raises(av.AvError, match="first layer"):
        d.build()
