"""One path from a target and its overrides to a diagram: `avblocks run`
(load_any) and a sweep's case (build_case) build the same thing, for a
scenario file, a Python-only built-in and a user's .py file."""

import numpy as np
import pytest

from avblocks.scenarios import builtin_scenarios
from avblocks.scenarios.targets import PythonScenario, load_any, open_scenario
from avblocks.sweep.spec import build_case, scenario_source

PY = '''
import numpy as np
import avblocks as av

def make_diagram(agents=3, gain=1.0, seed=0):
    d = av.Diagram("mine")
    rng = np.random.default_rng(seed)
    f = d.add(av.vehicles.Unicycle(rng.uniform(0, 5, (agents, 3))), name="fleet")
    p = d.add(av.controllers.PointToPoint(np.zeros((1, 2)), n=agents, gain=gain),
              name="drive")
    d.connect(f.pose, p.pose)
    d.connect(p.cmd, f.cmd)
    return d, {"t_final": 1.0}
'''


def _same(a, b):
    """Same blocks, simulate arguments, numeric parameters and initial states."""
    from avblocks.core.simulator import Simulator
    (d1, s1), (d2, s2) = a, b
    assert sorted(d1.blocks) == sorted(d2.blocks)
    assert s1.keys() - {"seed"} == s2.keys() - {"seed"}   # a sweep always seeds simulate
    for k in s1.keys() & s2.keys():
        if k == "params":
            assert s1[k].keys() == s2[k].keys()
            for p in s1[k]:
                np.testing.assert_array_equal(s1[k][p], s2[k][p])
        elif k != "log":
            assert s1[k] == s2[k], k
    c1, c2 = d1.build(), d2.build()
    v1, v2 = c1.param_values(), c2.param_values()
    assert v1.keys() == v2.keys()
    for k in v1:
        np.testing.assert_array_equal(v1[k], v2[k])
    for x1, x2 in zip(Simulator(c1, 0.1, "rk4", seed=5).initial_states(),
                      Simulator(c2, 0.1, "rk4", seed=5).initial_states()):
        assert x1.keys() == x2.keys()
        for k in x1:
            np.testing.assert_array_equal(np.asarray(x1[k]), np.asarray(x2[k]))


@pytest.mark.parametrize("target, values", [
    ("waypoints", {"agents": 4, "t_final": 2.0, "drive.gain": 2.5}),
    ("pursuit", {"agents": 2, "t_final": 2.0}),
    ("mine.py", {"agents": 4, "gain": 1.5, "drive.v_max": 0.5,
                 "simulation.t_final": 3.0}),
])
def test_a_run_and_a_sweep_case_build_the_same(target, values, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.py").write_text(PY)
    seed = 5
    case = build_case(scenario_source(target), values, seed)
    run = load_any(target, {**values, "seed": seed})
    _same(case, run[:2])
    assert case[1]["seed"] == seed
    if "drive.gain" in values or "drive.v_max" in values:
        key = "drive.gain" if "drive.gain" in values else "drive.v_max"
        np.testing.assert_allclose(case[1]["params"][key], values[key])   # checked once


def test_open_scenario_tells_files_from_python():
    module = str(builtin_scenarios()["pursuit"].with_suffix(".py"))    # pursuit.yaml's twin
    assert isinstance(open_scenario(module), PythonScenario)
    assert not isinstance(open_scenario("pursuit"), PythonScenario)
    assert not isinstance(open_scenario("waypoints"), PythonScenario)
    sc = open_scenario(module)
    assert sc.accepts("agents") and not sc.accepts("agent")
    with pytest.raises(Exception, match="did you mean 'agents'"):
        sc.with_overrides({"agent": 3})
