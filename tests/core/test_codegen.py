"""The generated NumPy major step (core.codegen) computes exactly what the
generic engine computes: bit for bit, on diagrams with every feature the
engine has (several rates and offsets, inherited sample times, feedthrough
chains, discrete states of continuous blocks, random keys, bare-array
outputs, RK4 stages that recompute only what feeds the states)."""

from __future__ import annotations

import numpy as np
import pytest

import avblocks as av
from avblocks.core import codegen


class Bare(av.Block):
    """One output returned as a bare array (allowed for one-output blocks)."""

    def __init__(self, n):
        super().__init__()
        self.declare_input("u", (n, 2))
        self.declare_output("y", (n, 2))

    def output(self, t, x, u, xp):
        return 0.5 * u["u"] + t


class Counter(av.Block):
    """Periodic counter with an offset; output (1,) = hits so far."""

    def __init__(self, period, offset=0.0):
        super().__init__()
        self.declare_periodic(period, offset)
        self.declare_discrete_state("c", np.zeros(1))
        self.declare_output("y", (1,))

    def output(self, t, x, u, xp):
        return {"y": x["c"] + t}

    def update(self, t, x, u, xp):
        return {"c": x["c"] + 1}


def _w1(n=6):
    rng = np.random.default_rng(0)
    p0 = np.column_stack([rng.uniform(0, 5, (n, 2)), rng.uniform(-3, 3, n)])
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(p0, v_max=0.8), name="fleet")
    c = d.add(av.controllers.PointToPoint(rng.uniform(0, 5, (n, 3, 2)), radius=0.5),
              name="drive")
    d.connect(f.pose, c.pose)
    d.connect(c.cmd, f.cmd)
    return d, ["fleet.pose", "drive.cmd", "drive.done", "drive.target"]


def _multirate():
    d = av.Diagram()
    a = d.add(Counter(0.03), name="a")
    b = d.add(Counter(0.05, offset=0.02), name="b")
    s = d.add(av.blocks.Sum("++"), name="s")
    z = d.add(av.blocks.ZeroOrderHold(period=0.04), name="z")
    g = d.add(av.blocks.Gain(2.0), name="g")           # inherits z's rate
    i = d.add(av.blocks.Integrator(np.zeros(1), agents=False), name="i")
    ud = d.add(av.blocks.UnitDelay(np.zeros(1), period=0.02), name="ud")
    d.connect(a.y, s.u0)
    d.connect(b.y, s.u1)
    d.connect(s.y, z.u)
    d.connect(z.y, g.u)
    d.connect(g.y, i.u)
    d.connect(i.y, ud.u)
    return d, ["a.y", "b.y", "s.y", "g.y", "i.y", "ud.y"]


def _random_walk_and_followers():
    d = av.Diagram()
    p0 = np.array([[0.0, 0, 0], [-1.0, 0.3, 0.2], [-2.0, -0.2, 0.1]])
    fleet = d.add(av.vehicles.Unicycle(p0), name="fleet")
    walk = d.add(av.controllers.RandomWalk(3, interval=("exponential", 0.05),
                                           bounds=(-3, -3, 3, 3)), name="walk")
    lf = d.add(av.controllers.LeaderFollower([-1, 0, 1], l_ref=1.0, alpha_ref=0.1),
               name="lf")
    bare = d.add(Bare(3), name="bare")
    d.connect(fleet.pose, walk.pose)
    d.connect(fleet.pose, lf.pose)
    d.connect(walk.cmd, lf.cmd_in)
    d.connect(lf.cmd, bare.u)
    d.connect(bare.y, fleet.cmd)
    return d, ["fleet.pose", "walk.cmd", "lf.error", "bare.y"]


def _flock():
    rng = np.random.default_rng(1)
    d = av.Diagram()
    ag = d.add(av.vehicles.DoubleIntegrator(rng.uniform(0, 3, (5, 2))), name="ag")
    nb = d.add(av.environment.Neighbors(5, 3, radius=2.0, input="position",
                                        period=0.02), name="nb")
    fl = d.add(av.controllers.Flocking(5, 1.0), name="fl")
    d.connect(ag.position, nb.position)
    d.connect(ag.position, fl.position)
    d.connect(ag.velocity, fl.velocity)
    d.connect(nb.neighbors, fl.neighbors)
    d.connect(fl.accel, ag.accel)
    return d, ["ag.position", "ag.velocity", "nb.neighbors", "fl.accel"]


CASES = {"w1": _w1, "multirate": _multirate, "walk": _random_walk_and_followers,
         "flock": _flock}


@pytest.mark.parametrize("solver", ["euler", "rk4"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_generated_step_equals_engine_bit_for_bit(case, solver, monkeypatch):
    runs = []
    for use in (True, False):
        monkeypatch.setattr(av.Simulator, "use_codegen", use)
        d, log = CASES[case]()
        sim = av.Simulator(d, 0.01, solver, seed=3)
        sim.init()
        assert (sim._fast is not None) == use
        trace = []
        for _ in range(60):
            sim.step()
            trace.append([np.array(sim.value(p)) for p in log])
        trace.append([np.array(v) for x in sim.X for k, v in x.items()])
        runs.append(trace)
    for a, b in zip(*runs, strict=True):
        for u, v in zip(a, b, strict=True):
            assert u.dtype == v.dtype and u.tobytes() == v.tobytes()


def test_variable_step_and_custom_solvers_use_the_engine():
    d, _ = _w1()
    assert av.Simulator(d, 0.01, "RK45").init()._fast is None
    assert codegen.supported(av.core.solvers.RK4())
    assert not codegen.supported(av.core.solvers.Scipy("RK45"))


def test_errors_still_name_the_block():
    class Boom(av.Block):
        def __init__(self):
            super().__init__()
            self.declare_input("u", (1, 1))
            self.declare_output("y", (1, 1))

        def output(self, t, x, u, xp):
            if t > 0.05:
                raise ZeroDivisionError("boom")
            return {"y": u["u"]}

    class Multi(av.Block):
        def __init__(self):
            super().__init__()
            self.declare_output("a", (1,))
            self.declare_output("b", (1,))

        def output(self, t, x, u, xp):
            return {"a": np.ones(1), "b": np.ones(1)} if t == 0 else np.ones(1)

    d = av.Diagram()
    c = d.add(av.blocks.Constant([[1.0]]), name="c")
    b = d.add(Boom(), name="boom")
    d.connect(c.y, b.u)
    with pytest.raises(av.SimulationError, match="boom") as e:
        av.simulate(d, 1.0, dt=0.01)
    assert e.value.block == "boom"
    d2 = av.Diagram()
    d2.add(Multi(), name="m")
    with pytest.raises(av.SimulationError, match="must return a dict") as e:
        av.simulate(d2, 1.0, dt=0.01)
    assert e.value.block == "m"


def test_generated_source_is_straight_line():
    d, _ = _w1()
    sim = av.Simulator(d, 0.01, "euler").init()
    src = sim._fast.source
    assert "for " not in src and "while " not in src
    # inputs resolved to the producing block's outputs, states updated in place
    assert "k1_0 = der0(t, x0, {'cmd': y1['cmd']}, np)" in src
    assert "x0 = {'pose': x0['pose'] + h * k1_0['pose']}" in src
    # RK4 stages recompute only what feeds a continuous state: the Sum in
    # front of the zero-order hold is not (the hold keeps its output)
    d, _ = _multirate()
    src = av.Simulator(d, 0.01, "rk4").init()._fast.source
    assert "der5(tm, s5, {'u': y4['y']}, np)" in src and "out2(tm" not in src


def test_compiled_code_is_reused_per_source_and_bound_per_simulator(monkeypatch):
    """Simulating the same structure again reuses the compiled code object
    (no second call to Python's compiler), while each simulator's step is
    bound to its own blocks: a diagram of another size and other values
    steps to its own results, those of the generic engine."""
    compiles = []

    def counting(*a, **k):
        compiles.append(a[1])
        return compile(*a, **k)

    monkeypatch.setattr(codegen, "compile", counting, raising=False)
    codegen._compiled.cache_clear()
    s1 = av.Simulator(_w1()[0], 0.01, "euler").init()
    s2 = av.Simulator(_w1()[0], 0.01, "euler").init()
    assert compiles == ["<avblocks generated step>"]
    assert s1._fast.__code__ is s2._fast.__code__ and s1._fast is not s2._fast
    s3 = av.Simulator(_w1()[0], 0.01, "rk4").init()      # other source, other code
    assert len(compiles) == 2 and s3._fast.__code__ is not s1._fast.__code__
    # the source names no sizes or values: 7 agents reuse the code, and step
    # as the generic engine steps them
    s4 = av.Simulator(_w1(n=7)[0], 0.01, "euler").init()
    assert len(compiles) == 2 and s4._fast.__code__ is s1._fast.__code__
    monkeypatch.setattr(av.Simulator, "use_codegen", False)
    ref = av.Simulator(_w1(n=7)[0], 0.01, "euler").init()
    for _ in range(20):
        s1.step()
        s4.step()
        ref.step()
    assert s4.X[0]["pose"].tobytes() == ref.X[0]["pose"].tobytes()
    assert s1.X[0]["pose"].shape == (6, 3)
    most = codegen._compiled.cache_parameters()["maxsize"]
    for j in range(most + 3):                            # bounded, oldest out
        codegen._compiled(f"x = {j}\n")
    assert codegen._compiled.cache_info().currsize == most
