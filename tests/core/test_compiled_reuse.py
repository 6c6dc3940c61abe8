"""A second ``simulate(backend="jax")`` of a diagram reuses the runner of the
first (no build, no compile), and every kind of in-place change it relies on
seeing is seen: parameter values, initial values, a block added (also inside
a subsystem), a structural attribute changed in place, other run settings.
Each run is checked against the NumPy engine."""

import os

import numpy as np
import pytest

import avblocks as av
from avblocks.core.compiled import build

if os.environ.get("CI"):
    import jax  # noqa: F401  (in CI the jax extra is installed: never skip)
else:
    pytest.importorskip("jax")
pytestmark = pytest.mark.jax

KW = dict(t_final=1.0, dt=0.05, solver="euler", log=["fleet.pose"])


class Law(av.Block):
    """Go-to-goal law; ``goal`` is a plain attribute (structure), ``k`` a
    declared parameter (data)."""

    def __init__(self, goal, k=1.0):
        super().__init__()
        self.goal = np.asarray(goal, float)
        n = len(self.goal)
        self.declare_parameter("k", k, ())
        self.declare_input("pose", (n, 3))
        self.declare_output("cmd", (n, 2))

    def output(self, t, x, u, xp):
        p = u["pose"]
        c, s = xp.cos(p[:, 2]), xp.sin(p[:, 2])
        ex = self.goal[:, 0] - p[:, 0] - 0.2 * c
        ey = self.goal[:, 1] - p[:, 1] - 0.2 * s
        return {"cmd": xp.stack([self.k * (c * ex + s * ey),
                                 self.k * (c * ey - s * ex) / 0.2], axis=-1)}


def fleet_diagram(seed=0, n=3):
    rng = np.random.default_rng(seed)
    p0 = np.column_stack([rng.uniform(-2, 2, (n, 2)), rng.uniform(-3, 3, n)])
    d = av.Diagram()
    fleet = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
    law = d.add(Law(rng.uniform(-2, 2, (n, 2)), k=0.8), name="law")
    d.connect(fleet.pose, law.pose)
    d.connect(law.cmd, fleet.cmd)
    return d


@pytest.fixture
def compiles(monkeypatch):
    """Counts the calls of the compiled engine's compile() by simulate."""
    calls = []
    real = build.compile

    def counting(*a, **k):
        calls.append(1)
        return real(*a, **k)
    monkeypatch.setattr(build, "compile", counting)
    return calls


def same_as_numpy(d, **kw):
    got = av.simulate(d, backend="jax", **{**KW, **kw})
    ref = av.simulate(d, **{**KW, **kw})
    np.testing.assert_allclose(got["fleet.pose"], ref["fleet.pose"], atol=1e-10)
    return got


def test_second_call_reuses_the_runner_and_reads_values_afresh(compiles):
    d = fleet_diagram()
    same_as_numpy(d)
    assert len(compiles) == 1
    same_as_numpy(d, seed=3, params={"law.k": 0.5}, x0={"fleet.pose": np.zeros((3, 3))})
    assert len(compiles) == 1                           # values only: reused
    d.build().blocks[d.build().index("law")].set_parameter("k", 1.7)
    same_as_numpy(d)
    d["fleet"].block.set_initial("pose", np.ones((3, 3)))
    same_as_numpy(d)
    assert len(compiles) == 1
    same_as_numpy(d, log_every=2)                       # other settings: compiled
    assert len(compiles) == 2


def test_a_structural_attribute_changed_in_place_is_seen(compiles):
    d = fleet_diagram(seed=1)
    before = same_as_numpy(d)
    d["law"].block.goal += 1.0                          # in place, not a parameter
    after = same_as_numpy(d)
    assert len(compiles) == 2
    assert np.max(np.abs(after["fleet.pose"] - before["fleet.pose"])) > 1e-3


def test_a_block_added_is_seen_also_inside_a_subsystem(compiles):
    d = fleet_diagram(seed=2)
    same_as_numpy(d)
    probe = d.add(av.blocks.Integrator(np.zeros((3, 3))), name="probe")
    d.connect(d["fleet"].pose, probe.u)
    got = same_as_numpy(d)
    assert len(compiles) == 2
    assert "probe.x" in got.final_state
    # a subsystem changed after it was added: its parent sees the change
    sub = av.Diagram()
    g = sub.add(av.blocks.Gain(2.0), name="g")
    sub.export_input("u", g.u)
    sub.export_output("y", g.y)
    s = d.add(sub, name="sub")
    d.connect(d["fleet"].pose, s.u)
    same_as_numpy(d)
    assert len(compiles) == 3
    j = sub.add(av.blocks.Integrator(np.zeros((3, 3))), name="j")
    sub.connect(g.y, j.u)
    got = same_as_numpy(d)
    assert len(compiles) == 4
    assert "sub.j.x" in got.final_state
    np.testing.assert_allclose(got.final_state["sub.j.x"],
                               av.simulate(d, **KW).final_state["sub.j.x"], atol=1e-10)


def test_log_given_as_an_iterator_is_read_once(compiles):
    d = fleet_diagram(seed=3)
    kw = {k: v for k, v in KW.items() if k != "log"}
    a = av.simulate(d, backend="jax", log=iter(["fleet.pose"]), **kw)
    b = av.simulate(d, backend="jax", log=iter(["fleet.pose"]), **kw)
    assert len(compiles) == 1
    np.testing.assert_array_equal(a["fleet.pose"], b["fleet.pose"])


def test_snapshot_sees_what_the_structure_key_sees():
    """The quick test before the key: True only when the key is the same."""
    import dataclasses

    from avblocks.core.compiled.structure import Snapshot, diagram_key

    @dataclasses.dataclass(frozen=True)
    class Rec:
        items: list

    d = fleet_diagram(seed=4)
    cd = d.build()
    law = cd.blocks[cd.index("law")]
    law.table = Rec([1, 2])                         # frozen, but not plain

    def changed(change):
        snap, key = Snapshot(cd), diagram_key(cd)
        change()
        same = snap.matches()
        assert not same or diagram_key(cd) == key   # never True on another key
        return not same

    assert not changed(lambda: None)
    assert not changed(lambda: law.set_parameter("k", 2.5))     # a value: data
    assert changed(lambda: law.goal.__setitem__((0, 0), 9.0))  # array in place
    assert changed(lambda: law.table.items.append(3))         # nested, in place
    assert changed(lambda: setattr(law, "extra", 1))
    assert changed(lambda: law.redeclare_output("cmd", (3, 2), "float32"))
    assert changed(lambda: law._feedthrough.discard("pose"))
