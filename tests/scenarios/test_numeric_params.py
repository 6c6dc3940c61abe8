"""Numeric block parameters from the command line (``--set drive.gain=2``)
and from a scenario's ``params:`` section, for YAML and Python scenarios."""

from __future__ import annotations

import numpy as np
import pytest

import avblocks as av
from avblocks.cli import main
from avblocks.core.errors import ScenarioError
from avblocks.scenarios import load_scenario

RAMP = """
name: ramp
parameters: {n: 2}
blocks:
  c: {type: blocks.Constant, value: {tile: {value: [1.0, 0.0], n: $n}}}
  g: {type: blocks.Gain, k: 1.0}
  fleet: {type: vehicles.Unicycle, pose0: {zeros: {shape: [$n, 3]}}, v_max: 5.0}
wires:
  - [c.y, g.u]
  - [g.y, fleet.cmd]
simulation: {t_final: 1.0, dt: 0.1, log: [fleet.pose]}
"""


def _write(tmp_path, text, name="s.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def test_yaml_params_section_and_set_override(tmp_path):
    # x(1) = v_eff * 1 s with v_eff = min(k, v_max): k = 3 from the file
    path = _write(tmp_path, RAMP + "params: {g.k: 3.0}\n")
    d, sim = load_scenario(path).build()
    assert sim["params"]["g.k"] == pytest.approx(3.0)
    res = av.simulate(d, **sim)
    assert res["fleet.pose"][-1, :, 0] == pytest.approx([3.0, 3.0], abs=1e-12)
    assert res.meta["params"] == {"g.k": 3.0}
    # --set overrides the file; a second block's limit too
    d, sim = load_scenario(path).with_overrides({"g.k": 4.0, "fleet.v_max": 2.5}).build()
    res = av.simulate(d, **sim)
    assert res["fleet.pose"][-1, :, 0] == pytest.approx([2.5, 2.5], abs=1e-12)
    # the block's own values are untouched afterwards (simulate restores them)
    assert d.build().get_param("g.k") == pytest.approx(1.0)


def test_cli_set_numeric_parameter_on_a_yaml_scenario(tmp_path, capsys):
    path = _write(tmp_path, RAMP)
    rc = main(["run", path, "--set", "g.k=2.0", "--out", str(tmp_path / "o"), "--quiet"])
    assert rc == 0
    res = av.Results.load(tmp_path / "o" / "results.nc")
    assert res["fleet.pose"][-1, :, 0] == pytest.approx([2.0, 2.0], abs=1e-12)


def test_cli_set_numeric_parameter_on_the_builtin_waypoints(tmp_path):
    """The built-in YAML scenario: a larger drive.v_max makes the fleet
    travel farther in the same time (and the value reaches the block)."""
    out = {}
    for vmax in (0.5, 1.5):
        o = tmp_path / f"v{vmax}"
        rc = main(["run", "waypoints", "--set", "agents=4", "--set",
                   "simulation.t_final=2", "--set", f"drive.v_max={vmax}",
                   "--out", str(o), "--quiet"])
        assert rc == 0
        res = av.Results.load(o / "results.nc")
        p = res["fleet.pose"]
        out[vmax] = np.hypot(*(p[-1, :, :2] - p[0, :, :2]).T)
    # the off-axis point moves at most v_max; the axle then too, up to d * dtheta
    assert np.all(out[0.5] <= 0.5 * 2 + 0.2 + 1e-9)
    assert np.all(out[1.5] > out[0.5])


PY = '''
import numpy as np
import avblocks as av

def make_diagram(n=2):
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.tile([1.0, 0.0], (n, 1))), name="c")
    g = d.add(av.blocks.Gain(1.0), name="g")
    f = d.add(av.vehicles.Unicycle(np.zeros((n, 3))), name="fleet")
    d.connect(c.y, g.u)
    d.connect(g.y, f.cmd)
    return d, {"t_final": 1.0, "dt": 0.1, "log": ["fleet.pose"]}
'''


def test_cli_set_numeric_parameter_on_a_python_scenario(tmp_path):
    path = _write(tmp_path, PY, "scen.py")
    rc = main(["run", path, "--set", "n=3", "--set", "g.k=0.5", "--out",
               str(tmp_path / "o"), "--quiet"])
    assert rc == 0
    res = av.Results.load(tmp_path / "o" / "results.nc")
    assert res["fleet.pose"][-1, :, 0] == pytest.approx([0.5] * 3, abs=1e-12)


@pytest.mark.parametrize("key,match", [
    ("g.kk=2", "did you mean"),               # typo in the parameter
    ("gg.k=2", "did you mean"),               # typo in the block
    ("g.k=[1, 2, 3]", "shape"),               # wrong shape
    ("fleet.v_max=-1", "lower bound"),        # out of bounds
])
def test_bad_numeric_keys_are_clear_errors(tmp_path, capsys, key, match):
    path = _write(tmp_path, RAMP)
    rc = main(["run", path, "--set", key, "--out", str(tmp_path / "o"), "--quiet"])
    assert rc == 2
    err = capsys.readouterr().err
    assert match in err and key.split("=")[0] in err


def test_bad_numeric_key_in_a_python_scenario_and_in_a_params_section(tmp_path):
    path = _write(tmp_path, PY, "scen.py")
    from avblocks.cli import load_any
    with pytest.raises(ScenarioError, match="did you mean"):
        load_any(path, {"g.kk": 1.0})
    bad = _write(tmp_path, RAMP + "params: {fleet.vmax: 1.0}\n", "bad.yaml")
    with pytest.raises(ScenarioError, match=r"params\.fleet\.vmax.*did you mean"):
        load_scenario(bad).build()
    bad2 = _write(tmp_path, RAMP + "params: [1, 2]\n", "bad2.yaml")
    with pytest.raises(ScenarioError, match="'params' must map"):
        load_scenario(bad2).build()
