"""The case studies as scenario files give the same runs as their Python
twins (the modules in avblocks.scenarios)."""

import importlib

import numpy as np
import pytest

import avblocks as av
from avblocks.cli import load_any
from avblocks.scenarios import builtin_scenarios, load_scenario


@pytest.mark.parametrize("name, sets", [
    ("nest", {"agents": 60, "t_final": 8.0}),
    ("swap", {"agents": 8, "t_final": 8.0}),
    ("swap", {"agents": 8, "t_final": 8.0, "mode": "joint"}),
    ("flocking", {"agents": 12, "t_final": 4.0}),
    ("formation", {"agents": 4, "t_final": 30.0, "dt": 0.05}),   # through the 1st switch
    # a source near the nest: found, brought home and the whole nest alarmed
    ("honeybee", {"agents": 60, "t_final": 60.0, "dt": 0.2, "source": [-22.0, 6.0]}),
    # the learning tasks: other counts, seeds, sizes and speeds than the defaults
    ("pursuit", {"agents": 5, "t_final": 4.0, "seed": 4, "half": 2.0, "speed": 1.3,
                 "evader_speed": 0.9}),
    ("spread", {"agents": 6, "t_final": 3.0, "seed": 5, "half": 1.5, "speed": 0.8}),
    ("navigation", {"agents": 5, "t_final": 3.0, "seed": 6, "rays": 8, "speed": 0.9,
                    "obstacles": [[0.2, 0.1, 0.6, 0.4], [-0.8, -0.7, 0.4, 0.4]]}),
])
def test_yaml_and_python_forms_give_the_same_run(name, sets):
    assert builtin_scenarios()[name].suffix == ".yaml"     # the file is what runs
    mod = importlib.import_module(f"avblocks.scenarios.{name}")
    d1, s1 = mod.make_diagram(**sets)
    r1 = av.simulate(d1, progress=False, **s1)
    d2, s2, *_ = load_any(name, sets)
    r2 = av.simulate(d2, progress=False, **s2)
    np.testing.assert_allclose(r2.t, r1.t)
    if name == "formation":
        assert np.ptp(np.asarray(r2["supervisor.mode"])) == 1          # it switched
    if name == "honeybee":      # every mode visited, every nest bee informed
        assert set(np.unique(np.asarray(r2["modes.mode"]))) == {0, 1, 2}
        assert np.asarray(r2["gossip.informed"])[-1, 12:].all()       # the nest
    assert len(r2.keys()) >= 2
    for k in r2.keys():
        np.testing.assert_allclose(np.asarray(r2[k], float), np.asarray(r1[k], float),
                                   rtol=0, atol=1e-9, err_msg=k)


def test_yaml_scenario_parameters_are_the_python_defaults():
    import inspect
    for name in ("nest", "swap", "flocking", "formation", "honeybee", "pursuit", "spread",
                 "navigation"):
        mod = importlib.import_module(f"avblocks.scenarios.{name}")
        defaults = {k: p.default for k, p in
                    inspect.signature(mod.make_diagram).parameters.items()}
        params = load_scenario(name).data["parameters"]
        for k, v in params.items():
            if isinstance(v, str) or defaults[k] is None:
                # a string (swap's mode) is the Python default itself
                assert defaults[k] == v or (k in ("tree", "agents")
                                            and defaults[k] is None), (name, k)
                continue
            assert np.allclose(np.asarray(v, float), np.asarray(defaults[k], float)), (name, k)


def test_unknown_report_name():
    sc = load_scenario("nest")
    sc.data["report"] = "nets"
    with pytest.raises(av.ScenarioError, match="did you mean 'nest'"):
        sc.validate()


def _summary(target, out, *sets):
    import json

    from avblocks.cli import main
    assert main(["run", str(target), *sets, "--quiet", "--out", str(out)]) == 0
    return json.loads((out / "summary.json").read_text())


def test_honeybee_file_and_module_give_the_same_summary(tmp_path):
    """The case study's outcome numbers (detection, return, all informed)
    from honeybee.yaml equal those of the module it twins."""
    sets = ["--set", "agents=60", "--set", "t_final=60", "--set", "dt=0.2",
            "--set", "source=[-22.0, 6.0]"]
    module = builtin_scenarios()["honeybee"].with_suffix(".py")
    a = _summary("honeybee", tmp_path / "yaml", *sets)
    b = _summary(module, tmp_path / "py", *sets)
    assert a["outcome"] == b["outcome"] and a["numbers"] == b["numbers"]
    assert a["numbers"]["detected_s"] < a["numbers"]["returned_s"] \
        < a["numbers"]["all_informed_s"] <= 60.0
    assert a["numbers"]["informed_at_end"] == 1.0
