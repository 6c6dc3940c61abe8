"""Build-time errors name the block, the port, what was expected and found."""

import numpy as np
import pytest

import avblocks as av


def fleet(d, n=3, name="fleet"):
    return d.add(av.vehicles.Unicycle(pose0=np.zeros((n, 3))), name=name)


def test_unknown_port():
    d = av.Diagram()
    f = fleet(d)
    with pytest.raises(av.WiringError, match=r"block 'fleet', port 'posee'.*unknown port"):
        _ = f.posee


def test_output_to_output_and_input_as_source():
    d = av.Diagram()
    f = fleet(d)
    g = fleet(d, name="g")
    with pytest.raises(av.WiringError, match="not an input port"):
        d.connect(f.pose, g.pose)
    with pytest.raises(av.WiringError, match="not an output port"):
        d.connect(f.cmd, g.cmd)


def test_two_drivers():
    d = av.Diagram()
    f = fleet(d)
    c1 = d.add(av.blocks.Constant(np.zeros((3, 2))), name="c1")
    c2 = d.add(av.blocks.Constant(np.zeros((3, 2))), name="c2")
    d.connect(c1.y, f.cmd)
    with pytest.raises(av.WiringError, match="already driven by c1.y"):
        d.connect(c2.y, f.cmd)


def test_unconnected_input():
    d = av.Diagram()
    fleet(d)
    with pytest.raises(av.WiringError, match=r"block 'fleet', port 'cmd': input is not connected"):
        d.build()


def test_shape_mismatch_and_agent_count():
    d = av.Diagram()
    f = fleet(d, n=3)
    c = d.add(av.blocks.Constant(np.zeros((3, 3))), name="c")
    with pytest.raises(av.ShapeError, match=r"expected \(3, 2\), found \(3, 3\)"):
        d.connect(c.y, f.cmd)
    c5 = d.add(av.blocks.Constant(np.zeros((5, 2))), name="c5")
    with pytest.raises(av.ShapeError, match="agent count mismatch: c5.y carries 5 agents"):
        d.connect(c5.y, f.cmd)


def test_dtype_mismatch():
    d = av.Diagram()
    f = fleet(d, n=2)
    c = d.add(av.blocks.Constant(np.zeros((2, 2), dtype=bool)), name="c")
    d.connect(c.y, f.cmd)  # bool -> float is a safe cast
    d2 = av.Diagram()

    class NeedsBool(av.Block):
        def __init__(self):
            super().__init__()
            self.declare_input("flag", (2,), "bool")

    nb = d2.add(NeedsBool(), name="nb")
    c2 = d2.add(av.blocks.Constant(np.zeros(2)), name="c2")
    with pytest.raises(av.ShapeError, match="dtype mismatch"):
        d2.connect(c2.y, nb.flag)


def test_shape_mismatch_found_at_build_for_inherited_shapes():
    d = av.Diagram()
    f = fleet(d, n=3)
    c = d.add(av.blocks.Constant(np.zeros((4, 2))), name="c")
    g = d.add(av.blocks.Gain(2.0), name="g")
    d.connect(c.y, g.u)
    d.connect(g.y, f.cmd)
    with pytest.raises(av.ShapeError, match="agent count mismatch: g.y carries 4 agents"):
        d.build()


def test_algebraic_loop_names_the_cycle():
    d = av.Diagram()
    a = d.add(av.blocks.Gain(0.5), name="a")
    b = d.add(av.blocks.Gain(0.5), name="b")
    s = d.add(av.blocks.Sum("++"), name="s")
    c = d.add(av.blocks.Constant(np.ones((1, 1))), name="c")
    d.connect(c.y, s.u0)
    d.connect(b.y, s.u1)
    d.connect(s.y, a.u)
    d.connect(a.y, b.u)
    # shapes of the cycle are inferred from the constant
    with pytest.raises(av.AlgebraicLoopError) as e:
        d.build()
    msg = str(e.value)
    for wire in ("a.y -> b.u", "b.y -> s.u1", "s.y -> a.u"):
        assert wire in msg
    assert len(e.value.cycle) == 3


def test_loop_through_state_is_fine():
    d = av.Diagram()
    i = d.add(av.blocks.Integrator(np.ones((1, 1))), name="i")
    k = d.add(av.blocks.Gain(-1.0), name="k")
    d.connect(i.y, k.u)
    d.connect(k.y, i.u)
    res = av.simulate(d, 1.0, dt=0.01, log=[i.y])
    assert res[i.y][-1, 0, 0] == pytest.approx(np.exp(-1.0), rel=1e-9)


def test_subsystem_exports_and_flattening():
    inner = av.Diagram()
    i = inner.add(av.blocks.Integrator(np.ones((1, 1))), name="int")
    k = inner.add(av.blocks.Gain(-2.0), name="k")
    inner.connect(i.y, k.u)
    inner.export_input("u", i.u)
    inner.export_output("y", i.y)
    inner.export_output("dy", k.y)
    outer = av.Diagram()
    sub = outer.add(inner, name="plant")
    # feed the gain back into the integrator through the subsystem's ports
    outer.connect(sub.dy, sub.u)
    cd = outer.build()
    assert set(cd.names) == {"plant.int", "plant.k"}
    res = av.simulate(outer, 0.5, dt=0.001, log=[sub.y])
    assert res[sub.y][-1, 0, 0] == pytest.approx(np.exp(-1.0), rel=1e-9)
    assert res["plant.int.y"] is res[sub.y]


def test_duplicate_names_and_objects():
    d = av.Diagram()
    b = av.blocks.Gain(1.0)
    d.add(b, name="g")
    with pytest.raises(av.WiringError, match="exists already"):
        d.add(av.blocks.Gain(1.0), name="g")
    with pytest.raises(av.WiringError, match="already in the diagram"):
        d.add(b, name="h")


def test_unknown_keyword_is_rejected():
    with pytest.raises(TypeError):
        av.vehicles.Unicycle(pose0=np.zeros((1, 3)), vmax=2.0)


@pytest.mark.parametrize("bad", [np.zeros((3, 2)), np.full((2, 3), np.nan), "abc"])
def test_bad_initial_poses(bad):
    with pytest.raises(av.ParameterError, match="pose0"):
        av.vehicles.Unicycle(pose0=bad)


def test_feedthrough_ancestors_stop_at_blocks_that_read_their_state():
    """What a block's output at one time reads at that time: itself and the
    blocks upstream through direct feedthrough (a gain passes its input
    through, an integrator's output is its state). Chain c -> g -> i -> h,
    and a constant k nobody reads."""
    from avblocks.core.engine import Engine
    d = av.Diagram()
    c = d.add(av.blocks.Constant([[1.0]]), name="c")
    g = d.add(av.blocks.Gain(2.0), name="g")
    i = d.add(av.blocks.Integrator([[0.0]]), name="i")
    h = d.add(av.blocks.Gain(3.0), name="h")
    d.add(av.blocks.Constant([[5.0]]), name="k")
    d.connect(c.y, g.u)
    d.connect(g.y, i.u)
    d.connect(i.y, h.u)
    cd = d.build()
    eng = Engine(cd, 0.1)
    at = {n: j for j, n in enumerate(cd.names)}

    def names(*blocks):
        return {cd.names[j] for j in eng.feedthrough_ancestors(at[b] for b in blocks)}
    assert names("h") == {"h", "i"}
    assert names("g") == {"g", "c"}
    assert names("i") == {"i"}
    assert names("h", "g") == {"h", "i", "g", "c"}
    assert names() == set()
