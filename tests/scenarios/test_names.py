"""Consistent --set names across scenarios, and "did you mean" for unknown
parameters, blocks, ports and scenario names."""

import inspect

import numpy as np
import pytest

import avblocks as av
from avblocks.cli import load_any, main
from avblocks.scenarios import builtin_scenarios, load_scenario

#: one drone tracking one robot: no agent count to change
SINGLE = {"uav_tracking"}


@pytest.mark.parametrize("name", sorted(set(builtin_scenarios()) - SINGLE))
def test_every_scenario_takes_agents_t_final_dt_seed(name):
    d, sim, *_ = load_any(name, {"agents": 7, "t_final": 1.5, "dt": 0.05, "seed": 3})
    assert sim["t_final"] == 1.5 and sim["dt"] == 0.05 and sim["seed"] == 3
    res = av.simulate(d, progress=False, **sim)
    pose = [k for k in res.keys() if k.endswith((".pose", ".position"))][0]
    assert res[pose].shape[1] in (7, 7 + 12)          # honeybee adds its 12 scouts
    assert res.t[-1] == pytest.approx(1.5)


@pytest.mark.parametrize("args, hint", [
    (["run", "nests"], "did you mean 'nest'?"),
    (["run", "nest", "--set", "agent=5"], "did you mean 'agents'?"),
    (["run", "waypoints", "--set", "agent=5"], "did you mean 'agents'?"),
    (["run", "waypoints", "--set", "simulation.t_fina=3"], "did you mean 't_final'?"),
])
def test_did_you_mean_on_the_command_line(args, hint, capsys, tmp_path):
    assert main([*args, "--out", str(tmp_path)]) == 2
    assert hint in capsys.readouterr().err


def test_did_you_mean_for_ports_blocks_and_block_parameters(tmp_path):
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(np.zeros((2, 3))), name="fleet")
    with pytest.raises(av.WiringError, match="did you mean 'pose'"):
        f.port("poses")
    text = open(load_scenario("waypoints").source).read()
    for old, new, hint in (("[fleet.pose, drive.pose]", "[fleet.pose, driver.pose]",
                            "did you mean 'drive'"),
                           ("v_max: $speed", "vmax: $speed", "did you mean 'v_max'"),
                           ("area: [$area, $area], min", "area: [$area, $arae], min",
                            "did you mean 'area'")):
        p = tmp_path / "w.yaml"
        p.write_text(text.replace(old, new))
        with pytest.raises(av.ScenarioError, match=hint):
            load_scenario(str(p)).build()


def test_python_scenarios_share_the_names():
    import importlib
    for name, path in builtin_scenarios().items():
        if path.suffix == ".py":
            mod = importlib.import_module(f"avblocks.scenarios.{name}")
            ps = inspect.signature(mod.make_diagram).parameters
            need = {"t_final", "dt", "seed"} | (set() if name in SINGLE else {"agents"})
            assert need <= set(ps), name
