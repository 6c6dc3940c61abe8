"""The step loop's packed carry (avblocks.core.compiled.carry): packing gives
back every value bit for bit, it is used where the step is short elementwise
work and not where it sorts or reduces, and a packed run (single, ensemble,
gradient) equals the same run unpacked and the NumPy engine."""

import os

import numpy as np
import pytest

import avblocks as av
from avblocks.core.compiled import carry as C
from avblocks.core.compiled import clear_cache

if os.environ.get("CI"):
    import jax  # in CI the jax extra is installed: never skip
else:
    jax = pytest.importorskip("jax")
jnp = jax.numpy
pytestmark = pytest.mark.jax


def _w1(n=6, seed=1):
    """Go-to-goal unicycles with an arrival latch (a float and a boolean
    state that share the heading's trig)."""
    rng = np.random.default_rng(seed)
    p0 = np.column_stack([rng.uniform(0, 6, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    d = av.Diagram()
    fleet = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
    drive = d.add(av.controllers.PointToPoint(rng.uniform(0, 6, (n, 1, 2)), d=0.1,
                                              gain=1.0, v_max=1.0, radius=0.5),
                  name="drive")
    d.connect(fleet.pose, drive.pose)
    d.connect(drive.cmd, fleet.cmd)
    return d


def test_pack_unpack_is_exact_for_every_dtype_it_takes():
    rng = np.random.default_rng(0)
    tree = {"f": rng.normal(size=(5, 3)), "b": rng.random(5) < 0.5,
            "i": rng.integers(-2**31, 2**31 - 1, (5, 2), dtype=np.int32),
            "u8": rng.integers(0, 255, 5, dtype=np.uint8),
            "f32": rng.normal(size=(5, 2, 2)).astype(np.float32),
            "i64": rng.integers(-2**62, 2**62, 5),          # not exact in f64: apart
            "s": np.float64(np.pi), "empty": np.zeros((0, 3)),
            "special": np.array([np.nan, -0.0, np.inf, -np.inf, 5e-324])}
    with jax.enable_x64(True):
        leaves = jax.tree_util.tree_leaves(tree)
        pk = C.Packing(tree, np.float64)
        bufs, others = pk.pack(leaves)
        # the agent-length leaves share one buffer, the rest stay as they are
        assert [(n, b.shape) for (n, _), b in zip(pk.groups, bufs)] == [(5, (5, 12))]
        assert sorted(str(np.dtype(o.dtype)) for o in others) == \
            ["float64", "float64", "int64"]
        back = pk.unpack_flat((bufs, others))
    for a, b in zip(leaves, back):
        assert np.dtype(b.dtype) == np.asarray(a).dtype and b.shape == np.shape(a)
        assert np.asarray(b).tobytes() == np.asarray(a).tobytes()


def _step_jaxpr(fn, *args):
    with jax.enable_x64(True):
        return jax.make_jaxpr(fn)(*args).jaxpr


def test_only_short_elementwise_steps_are_packed():
    x = np.ones((8, 2))

    def law(x):
        return x + 0.01 * jnp.stack([jnp.cos(x[:, 1]), jnp.sin(x[:, 0])], axis=1)

    assert C.worth_packing(_step_jaxpr(law, x))
    # a sort, a reduction over the agents, a product: kernels of their own
    assert not C.worth_packing(_step_jaxpr(lambda x: law(jnp.sort(x, axis=0)), x))
    assert not C.worth_packing(_step_jaxpr(lambda x: law(x) - x.mean(0), x))
    assert not C.worth_packing(_step_jaxpr(lambda x: x @ jnp.eye(2), x))
    # also inside a branch
    assert not C.worth_packing(_step_jaxpr(
        lambda x: jax.lax.cond(x[0, 0] > 0, jnp.sort, law, x), x))

    # a long step (more operations than MAX_PACKED_OPS) is not packed
    def long(x):
        for _ in range(C.MAX_PACKED_OPS + 1):
            x = x * 1.0001
        return x
    assert not C.worth_packing(_step_jaxpr(long, x))


_WORTH = C.worth_packing


def _runs(monkeypatch, limit):
    monkeypatch.setattr(C, "MAX_PACKED_OPS", limit)
    clear_cache()
    decided = []
    monkeypatch.setattr(C, "worth_packing",
                        lambda j: decided.append(_WORTH(j)) or decided[-1])
    kw = dict(dt=0.01, solver="euler", log=["fleet.pose", "drive.done"], log_every=7)
    single = av.simulate(_w1(), 5.0, backend="jax", **kw)
    run = av.compile(_w1(), 5.0, **kw)
    gains = np.linspace(0.5, 1.5, 3)[:, None] * np.ones((3, 6))
    ens = run.ensemble(params={"drive.gain": gains})
    val, grad = run.value_and_grad(lambda r: jnp.sum(r["fleet.pose"][-1, :, :2] ** 2),
                                   ["drive.gain", "fleet.pose@x0"])
    return decided, single, ens, val, grad


def test_packed_runs_equal_unpacked_runs_and_the_numpy_engine(monkeypatch):
    packed = _runs(monkeypatch, C.MAX_PACKED_OPS)
    plain = _runs(monkeypatch, -1)
    clear_cache()
    assert packed[0] and all(packed[0]) and not any(plain[0])
    for port in ("fleet.pose", "drive.done"):
        np.testing.assert_array_equal(packed[1][port], plain[1][port])
        np.testing.assert_array_equal(packed[2][port], plain[2][port])
    for k, v in plain[1].final_state.items():
        np.testing.assert_array_equal(packed[1].final_state[k], v)
    assert packed[3] == plain[3]
    for k in plain[4]:
        np.testing.assert_allclose(packed[4][k], plain[4][k], rtol=1e-12, atol=0)
    # independent truth: the NumPy engine
    ref = av.simulate(_w1(), 5.0, dt=0.01, solver="euler", log=["fleet.pose", "drive.done"],
                      log_every=7, progress=False)
    np.testing.assert_allclose(packed[1]["fleet.pose"], ref["fleet.pose"], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(packed[1]["drive.done"], ref["drive.done"])
    assert ref["drive.done"][-1].any() and not ref["drive.done"][0].all()
