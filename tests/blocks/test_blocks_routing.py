import numpy as np
import pytest

import avblocks as av
from avblocks.blocks import Concatenate, Demux, Gather, Mux, Select
from avblocks.core.check import check_block

U = np.arange(15.0).reshape(5, 3)    # 5 agents, 3 components: U[i] = [3i, 3i+1, 3i+2]


def _one(blk, *values, ins=None, outs=("y",)):
    """Wire constants into ``blk`` and return its outputs at t = 0."""
    d = av.Diagram()
    b = d.add(blk, name="b")
    if ins is not None:
        names = ins
    else:
        names = [f"u{j}" for j in range(len(values))] if len(values) > 1 else ["u"]
    for j, (nm, v) in enumerate(zip(names, values)):
        c = d.add(av.blocks.Constant(v), name=f"c{j}")
        d.connect(c.y, b.port(nm))
    res = av.simulate(d, 0.0, dt=0.1, log=[b.port(o) for o in outs])
    return [res[b.port(o)][0] for o in outs]


def test_select_picks_agents_in_order():
    (y,) = _one(Select([4, 0, -2]), U)
    np.testing.assert_array_equal(y, [[12, 13, 14], [0, 1, 2], [9, 10, 11]])
    (y,) = _one(Select(np.array([True, False, False, True, False])), U)
    np.testing.assert_array_equal(y, U[[0, 3]])


def test_select_out_of_range_is_a_shape_error():
    d = av.Diagram()
    c = d.add(av.blocks.Constant(U), name="c")
    s = d.add(Select([1, 5]), name="s")
    d.connect(c.y, s.u)
    with pytest.raises(av.ShapeError, match="out of range") as e:
        d.build()
    assert e.value.found == [5]
    with pytest.raises(av.ParameterError):
        Select([[0, 1]])
    with pytest.raises(av.ParameterError):
        Select([0.5])


def test_gather_maps_each_agent_to_its_leader():
    leader = [0, 0, 1, 2, 2, 4]
    (y,) = _one(Gather(leader), U)
    assert y.shape == (6, 3)
    for i, j in enumerate(leader):
        np.testing.assert_array_equal(y[i], U[j])


def test_gather_with_a_dynamic_index_port():
    d = av.Diagram()
    u = d.add(av.blocks.Constant(U), name="u")
    idx = d.add(av.blocks.Constant(np.array([3, 1])), name="idx")
    g = d.add(Gather(), name="g")
    d.connect(u.y, g.u)
    d.connect(idx.y, g.index)
    res = av.simulate(d, 0.0, dt=0.1, log=[g.y])
    np.testing.assert_array_equal(res[g.y][0], U[[3, 1]])
    d = av.Diagram()
    u = d.add(av.blocks.Constant(U), name="u")
    idx = d.add(av.blocks.Constant([3.0, 1.0]), name="idx")
    g = d.add(Gather(), name="g")
    d.connect(u.y, g.u)
    with pytest.raises(av.ShapeError):
        d.connect(idx.y, g.index)
        d.build()


def test_concatenate_stacks_agent_sets():
    leader = np.array([[100.0, 101.0, 102.0]])
    (y,) = _one(Concatenate(["leader", "followers"]), leader, U, ins=["leader", "followers"])
    np.testing.assert_array_equal(y, np.vstack([leader, U]))
    d = av.Diagram()
    a = d.add(av.blocks.Constant(np.zeros((2, 3))), name="a")
    b = d.add(av.blocks.Constant(np.zeros((2, 2))), name="b")
    c = d.add(Concatenate(2), name="c")
    d.connect(a.y, c.u0)
    d.connect(b.y, c.u1)
    with pytest.raises(av.ShapeError, match="beyond the agent axis") as e:
        d.build()
    assert e.value.port == "u1"


def test_mux_stacks_components():
    x, y_, th = U[:, 0], U[:, 1], U[:, 2]
    (y,) = _one(Mux(3), x, y_, th)
    np.testing.assert_array_equal(y, U)
    (y,) = _one(Mux(["position", "heading"]), U[:, :2], th, ins=["position", "heading"])
    np.testing.assert_array_equal(y, U)
    (y,) = _one(Mux(2), U, U[:, :1])
    np.testing.assert_array_equal(y, np.hstack([U, U[:, :1]]))


def test_mux_rejects_different_agent_counts():
    d = av.Diagram()
    a = d.add(av.blocks.Constant(np.zeros((2, 2))), name="a")
    b = d.add(av.blocks.Constant(np.zeros(3)), name="b")
    m = d.add(Mux(2), name="m")
    d.connect(a.y, m.u0)
    d.connect(b.y, m.u1)
    with pytest.raises(av.ShapeError, match="leading axes") as e:
        d.build()
    assert e.value.port == "u1"


def test_demux_splits_components():
    outs = _one(Demux(3, names=["x", "y", "theta"]), U, outs=("x", "y", "theta"))
    for j, o in enumerate(outs):
        np.testing.assert_array_equal(o, U[:, j])
    p, h = _one(Demux([2, 1]), U, outs=("y0", "y1"))
    np.testing.assert_array_equal(p, U[:, :2])
    np.testing.assert_array_equal(h, U[:, 2:])
    d = av.Diagram()
    c = d.add(av.blocks.Constant(U), name="c")
    s = d.add(Demux([2, 2]), name="s")
    d.connect(c.y, s.u)
    with pytest.raises(av.ShapeError, match="last axis"):
        d.build()
    with pytest.raises(av.ParameterError):
        Demux([2, 0])
    with pytest.raises(av.ParameterError):
        Demux(2, names=["a"])


def test_mux_then_demux_round_trip_in_a_simulation():
    d = av.Diagram()
    s = d.add(av.blocks.Sine([1.0, 2.0, 3.0], 0.5), name="s")
    c = d.add(av.blocks.Clock(), name="c")
    g = d.add(av.blocks.Gain(np.ones(3)), name="g")
    m = d.add(Mux(2), name="m")
    dm = d.add(Demux(2), name="dm")
    d.connect(c.y, g.u)
    d.connect(s.y, m.u0)
    d.connect(g.y, m.u1)
    d.connect(m.y, dm.u)
    res = av.simulate(d, 1.0, dt=0.1, log=[dm.y0, dm.y1, s.y])
    np.testing.assert_array_equal(res[dm.y0], res[s.y])
    np.testing.assert_allclose(res[dm.y1], np.repeat(res.t[:, None], 3, axis=1))


@pytest.mark.parametrize("make, shapes", [
    (lambda n: Select([0, n - 1]), lambda n: {"u": (n, 3)}),
    (lambda n: Gather(np.arange(n)[::-1]), lambda n: {"u": (n, 2)}),
    (lambda n: Gather(m=2), lambda n: {"u": (n, 2), "index": ((2,), "int64")}),
    (lambda n: Concatenate(2), lambda n: {"u0": (n, 3), "u1": (2, 3)}),
    (lambda n: Mux(2), lambda n: {"u0": (n, 2), "u1": (n,)}),
    (lambda n: Demux([1, 2]), lambda n: {"u": (n, 3)}),
])
def test_conformance(make, shapes, configured):
    # a block instance (no agent count): routing changes the number of agents
    for n in (1, 7):
        assert check_block(configured(make(n), **shapes(n))).ok
