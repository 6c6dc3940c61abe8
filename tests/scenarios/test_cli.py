"""The command line and scenario files: runs, outputs, and clear errors."""

import json
import subprocess
import sys

import numpy as np
import pytest

import avblocks as av
from avblocks.cli import main
from avblocks.scenarios import load_scenario


def test_builtin_scenario_run_writes_its_files(tmp_path, capsys):
    rc = main(["run", "waypoints", "--set", "agents=6", "--set", "simulation.t_final=5",
               "--out", str(tmp_path), "--quiet"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "agents        6" in out and "real-time x" in out
    res = av.Results.load(tmp_path / "results.nc")
    assert res["fleet.pose"].shape[1:] == (6, 3)
    assert res.t[-1] == pytest.approx(5.0)
    png = (tmp_path / "waypoints.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["agents"] == 6 and summary["simulated_s"] == pytest.approx(5.0)


def test_scaling_changes_only_parameters():
    sc = load_scenario("waypoints")
    for n in (3, 40):
        d, sim = sc.with_overrides({"agents": n}).build()
        assert d.build().blocks[0].n == n or d.build().blocks[1].n == n
        assert sorted(d.blocks) == ["drive", "fleet"]


def write(tmp_path, text, name="s.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


GOOD = """
name: tiny
parameters: {n: 2}
blocks:
  fleet: {type: vehicles.Unicycle, pose0: {zeros: {shape: [$n, 3]}}}
  c: {type: blocks.Constant, value: {tile: {value: [1.0, 0.0], n: $n}}}
wires:
  - [c.y, fleet.cmd]
simulation: {t_final: 1.0, dt: 0.1}
"""


def test_yaml_and_toml_files(tmp_path):
    d, sim = load_scenario(write(tmp_path, GOOD)).build()
    res = av.simulate(d, **sim)
    assert res["fleet.pose"][-1, :, 0] == pytest.approx([1.0, 1.0])
    toml = """
name = "tiny"
[parameters]
n = 2
[blocks.fleet]
type = "vehicles.Unicycle"
pose0 = { zeros = { shape = ["$n", 3] } }
[blocks.c]
type = "blocks.Constant"
value = { tile = { value = [1.0, 0.5], n = "$n" } }
wires = []
"""
    toml = toml.replace("wires = []\n", "") + 'wires = [["c.y", "fleet.cmd"]]\n'
    # TOML top-level keys must come before tables
    toml = 'wires = [["c.y", "fleet.cmd"]]\n' + toml.replace(
        'wires = [["c.y", "fleet.cmd"]]\n', "")
    d, _ = load_scenario(write(tmp_path, toml, "s.toml")).build()
    res = av.simulate(d, 2.0, dt=0.1)
    assert res["fleet.pose"][-1, 0, 2] == pytest.approx(1.0)


@pytest.mark.parametrize("text,match", [
    (GOOD.replace("vehicles.Unicycle", "vehicles.Unicycel"),
     r"blocks.fleet.type: unknown block type 'vehicles.Unicycel'. "
     r"did you mean 'vehicles.Unicycle'"),
    (GOOD.replace("pose0:", "posee:"), r"blocks.fleet.posee: unknown parameter 'posee'"),
    (GOOD.replace("{zeros: {shape: [$n, 3]}}", "hello"), r"blocks.fleet.*pose0.*numeric"),
    (GOOD.replace("  - [c.y, fleet.cmd]\n", ""), r"fleet.*cmd.*not connected"),
    (GOOD.replace("[c.y, fleet.cmd]", "[c.y, flet.cmd]"),
     r"wires\[0\]: wire names unknown block 'flet'"),
    (GOOD.replace("$n, 3", "$m, 3"), r"unknown parameter reference '\$m'"),
    (GOOD + "extras: 1\n", r"unknown section"),
    (GOOD.replace("dt: 0.1", "dtt: 0.1"), r"unknown simulation setting"),
    ("blocks: [1, 2", r"cannot parse"),
    (GOOD.replace("{zeros: {shape: [$n, 3]}}", "{zeros: {shap: [2, 3]}}"),
     r"bad arguments for 'zeros'"),
])
def test_bad_scenarios_get_one_clear_error(tmp_path, text, match):
    path = write(tmp_path, text)
    with pytest.raises(av.ScenarioError, match=match) as e:
        load_scenario(path).build()
    assert path in str(e.value)


def test_cli_prints_one_line_error_not_a_traceback(tmp_path):
    path = write(tmp_path, GOOD.replace("vehicles.Unicycle", "vehicles.Nope"))
    r = subprocess.run([sys.executable, "-m", "avblocks", "run", path], capture_output=True,
                       text=True)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert r.stderr.startswith("avblocks: error:") and "vehicles.Nope" in r.stderr


def test_scenario_files_never_execute_code(tmp_path):
    evil = GOOD.replace("{zeros: {shape: [$n, 3]}}", "!!python/object/apply:os.system ['echo hi']")
    with pytest.raises(av.ScenarioError, match="cannot parse"):
        load_scenario(write(tmp_path, evil))


def test_python_file_scenario(tmp_path):
    src = '''
import numpy as np
import avblocks as av

def make_diagram(n=3):
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=np.zeros((n, 3))), name="fleet")
    c = d.add(av.blocks.Constant(np.tile([1.0, 0.0], (n, 1))), name="c")
    d.connect(c.y, f.cmd)
    return d, {"t_final": 2.0, "dt": 0.1}
'''
    p = write(tmp_path, src, "mine.py")
    rc = main(["run", p, "--set", "n=4", "--out", str(tmp_path / "o"), "--quiet"])
    assert rc == 0
    res = av.Results.load(tmp_path / "o" / "results.nc")
    assert res["fleet.pose"].shape == (21, 4, 3)
    assert np.allclose(res["fleet.pose"][-1, :, 0], 2.0)


def test_version_and_list(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert av.__version__ in capsys.readouterr().out
    assert main(["list"]) == 0
    assert "waypoints" in capsys.readouterr().out
    assert main(["list", "--blocks"]) == 0
    assert "vehicles.Unicycle" in capsys.readouterr().out


def test_builtin_python_scenario_with_simulation_override_and_movie(tmp_path, monkeypatch):
    pytest.importorskip("imageio_ffmpeg")
    (tmp_path / "formation").mkdir()          # a folder named like the scenario
    monkeypatch.chdir(tmp_path)
    rc = main(["run", "formation", "--set", "simulation.t_final=3", "--set", "agents=3",
               "--out", "o", "--movie", "o/f.gif", "--quiet"])
    assert rc == 0
    res = av.Results.load(tmp_path / "o" / "results.nc")
    assert res.t[-1] == pytest.approx(3.0)
    assert res["fleet.pose"].shape[1] == 3
    from PIL import Image
    assert Image.open(tmp_path / "o" / "f.gif").n_frames > 5
    with pytest.raises(av.ScenarioError, match="unknown parameter"):
        from avblocks.cli import load_any
        load_any("formation", {"folowers": 2})
