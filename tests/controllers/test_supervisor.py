"""Supervisor and AgentModes: scripted runs, no-match keeps state, bad definitions."""

import numpy as np
import pytest

import avblocks as av
from avblocks.controllers import AgentModes, Supervisor, formation


def _formation_supervisor():
    lines = {s: formation(s, 3, 1.0)[1] for s in ("line", "column", "wedge")}
    return Supervisor(
        ["line", "column", "wedge"],
        [("line", "column", lambda u, xp: u["width"] < 2.0),
         ("column", "wedge", lambda u, xp: u["width"] > 5.0),
         ("column", "line", lambda u, xp: u["width"] > 3.0),
         ("wedge", "line", lambda u, xp: u["t"] > 9.0)],
        initial="line", inputs={"width": ()},
        outputs={"l_ref": lines, "code": {"line": 0, "column": 1, "wedge": 2}})


def test_scripted_inputs_give_expected_states_and_outputs():
    sup = _formation_supervisor()
    d = av.Diagram()
    w = d.add(av.blocks.Step(time=2.0, before=4.0, after=1.0, agents=False), name="w1")
    w2 = d.add(av.blocks.Step(time=5.0, before=0.0, after=5.0, agents=False), name="w2")
    tot = d.add(_Add(), name="tot")
    d.connect(w.y, tot.a)
    d.connect(w2.y, tot.b)
    sv = d.add(sup, name="sup")
    d.connect(tot.y, sv.width)
    res = av.simulate(d, 12.0, dt=0.5, log=[sv.mode, sv.code, sv.l_ref, tot.y])
    t, mode = res.t, res[sv.mode]
    # width: 4 (no transition from line), 1 after t=2 (-> column), 6 after t=5
    # (-> wedge: first listed true guard wins over column->line), t > 9 -> line
    want = np.where(t <= 2.0, 0, np.where(t <= 5.0, 1, np.where(t <= 9.5, 2, 0)))
    np.testing.assert_array_equal(mode, want)
    np.testing.assert_array_equal(res[sv.code], want)
    np.testing.assert_allclose(res[sv.l_ref][-1], formation("line", 3, 1.0)[1])
    np.testing.assert_allclose(res[sv.l_ref][t == 4.0][0], formation("column", 3, 1.0)[1])


class _Add(av.Block):
    def __init__(self):
        super().__init__()
        self.declare_input("a", (), agents=False)
        self.declare_input("b", (), agents=False)
        self.declare_output("y", (), agents=False)

    def output(self, t, x, u, xp):
        return {"y": u["a"] + u["b"]}


def test_no_matching_transition_keeps_state():
    sup = _formation_supervisor()
    x = sup.initial_state()
    for width in (4.0, 2.5, 100.0):
        x = sup.update(0.0, x, {"width": np.array(width)}, np)
        assert sup.states[int(x["mode"])] == "line"
    x = sup.update(0.0, x, {"width": np.array(1.0)}, np)
    x = sup.update(0.0, x, {"width": np.array(2.5)}, np)   # column: 2.5 matches nothing
    assert sup.states[int(x["mode"])] == "column"


def test_illegal_definitions_rejected():
    g = lambda u, xp: True  # noqa: E731
    with pytest.raises(av.ParameterError, match="unique"):
        Supervisor(["a", "a"], [], initial="a")
    with pytest.raises(av.ParameterError, match="unknown state"):
        Supervisor(["a", "b"], [("a", "c", g)], initial="a")
    with pytest.raises(av.ParameterError, match="initial"):
        Supervisor(["a", "b"], [("a", "b", g)], initial="z")
    with pytest.raises(av.ParameterError, match="unreachable"):
        Supervisor(["a", "b", "c"], [("a", "b", g)], initial="a")
    with pytest.raises(av.ParameterError, match="callable"):
        Supervisor(["a", "b"], [("a", "b", "yes")], initial="a")
    with pytest.raises(av.ParameterError, match="every state"):
        Supervisor(["a", "b"], [("a", "b", g)], initial="a", outputs={"k": {"a": 1}})


def test_from_statemachine():
    statemachine = pytest.importorskip("statemachine")
    from statemachine import State, StateMachine

    class Formations(StateMachine):
        line = State(initial=True)
        column = State()
        step = line.to(column, cond="narrow") | column.to(line, cond="wide")

    sup = Supervisor.from_statemachine(
        Formations, inputs={"width": ()},
        guards={"narrow": lambda u, xp: u["width"] < 2, "wide": lambda u, xp: u["width"] > 3})
    x = sup.initial_state()
    seq = []
    for w in (5, 1, 2.5, 4, 4):
        x = sup.update(0.0, x, {"width": np.array(float(w))}, np)
        seq.append(sup.states[int(x["mode"])])
    assert seq == ["line", "column", "column", "line", "line"]
    with pytest.raises(av.ParameterError, match="guard"):
        Supervisor.from_statemachine(Formations, guards={"narrow": lambda u, xp: True})
    with pytest.raises(statemachine.exceptions.InvalidDefinition):
        class Bad(StateMachine):
            a = State(initial=True)
            b = State()
            c = State()
            go = a.to(b)


def test_agent_modes_vectorized():
    n = 5
    modes = AgentModes(
        n, ["searching", "informed", "returning"],
        [("searching", "informed", lambda u, xp: u["signal"] > 0.5),
         ("informed", "returning", lambda u, xp: u["t"] >= 2.0),
         ("returning", "searching", lambda u, xp: u["home"])],
        initial="searching", inputs={"signal": (n,), "home": ((n,), "bool")},
        outputs={"speed": {"searching": 1.0, "informed": 2.0, "returning": 0.5}})
    x = modes.initial_state()
    sig = np.array([0.0, 1.0, 0.7, 0.0, 0.2])
    home = np.array([True, True, False, False, True])
    x = modes.update(0.0, x, {"signal": sig, "home": home}, np)
    np.testing.assert_array_equal(x["mode"], [0, 1, 1, 0, 0])
    x = modes.update(2.0, x, {"signal": sig, "home": home}, np)
    np.testing.assert_array_equal(x["mode"], [0, 2, 2, 0, 0])
    x = modes.update(3.0, x, {"signal": sig * 0, "home": home}, np)
    np.testing.assert_array_equal(x["mode"], [0, 0, 2, 0, 0])
    np.testing.assert_allclose(modes.output(0, x, {}, np)["speed"], [1, 1, 0.5, 1, 1])
