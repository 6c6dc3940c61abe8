"""drone_formation.yaml is the case study: it runs to the summary the
Python module gave before it had a file (numbers kept from that run), the
same run as its Python twin, and its parameters are the module's."""

import importlib
import inspect
import json

import numpy as np
import pytest

import avblocks as av
from avblocks.cli import load_any, main
from avblocks.scenarios import builtin_scenarios, load_scenario

#: ``avblocks run drone_formation --set t_final=8`` on main before the file
#: existed (commit cf15bf0, the Python module): the independent truth.
MAIN_T8 = {"formation_rms_m": 0.07775268409147504, "formation_max_m": 0.150076471305574,
           "min_separation_m": 0.8934209065279947}


def test_the_file_runs_to_mains_summary(tmp_path):
    assert builtin_scenarios()["drone_formation"].suffix == ".yaml"
    out = tmp_path / "out"
    assert main(["run", "drone_formation", "--set", "t_final=8", "--quiet",
                 "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "complete" and s["agents"] == 5 and s["simulated_s"] == 8.0
    assert s["numbers"] == MAIN_T8
    assert s["outcome"] == ("formation: RMS error 0.078 m, max 0.150 m after 6 s; "
                            "min separation 0.89 m")
    assert (out / "paths.png").is_file()


def test_file_and_module_give_the_same_run():
    sets = {"agents": 4, "t_final": 10.0, "gather": 4.0, "radius": 1.2}
    mod = importlib.import_module("avblocks.scenarios.drone_formation")
    d1, s1 = mod.make_diagram(**sets)
    r1 = av.simulate(d1, progress=False, **s1)
    d2, s2, *_ = load_any("drone_formation", sets)
    r2 = av.simulate(d2, progress=False, **s2)
    assert sorted(r1.keys()) == sorted(r2.keys())
    for k in r1.keys():
        np.testing.assert_array_equal(np.asarray(r2[k]), np.asarray(r1[k]), err_msg=k)
    # the formation formed: every vehicle near its slot after the gather
    e = np.linalg.norm(np.asarray(r2["fleet.position"]) - np.asarray(r2["ref.position"]),
                       axis=-1)
    assert e[np.asarray(r2.t) >= 6.0].max() < 0.2


def test_file_parameters_are_the_module_defaults():
    mod = importlib.import_module("avblocks.scenarios.drone_formation")
    defaults = {k: p.default for k, p in
                inspect.signature(mod.make_diagram).parameters.items()}
    params = load_scenario("drone_formation").data["parameters"]
    assert params == defaults == mod.PARAMS


def test_the_fleet_is_one_block_that_robots_replace():
    """``--robots mavlink`` / ``crazyflies`` replace the block ``fleet`` as a
    whole: in the file it is one velocity-controlled quadrotor subsystem."""
    from avblocks.interfaces.flight.swap import find_flyer
    d, _sim, *_ = load_any("drone_formation", {})
    assert find_flyer(d) == "fleet"
    fleet = d["fleet"].block
    assert isinstance(fleet, av.vehicles.VelocityControlledQuadrotor)
    assert sorted(fleet.input_ports) == ["velocity"]
    assert fleet.input_ports["velocity"].shape == (5, 3)


def test_min_separation_is_the_3d_closest_pair_with_memory_linear_in_vehicles():
    import tracemalloc

    from avblocks.scenarios.drone_formation import min_separation
    rng = np.random.default_rng(5)
    p = rng.uniform(0, 10, size=(6, 30, 3))
    p[4, 7] = p[4, 19] + [0.0, 0.0, 0.013]      # one pair apart in height only
    brute = min(np.linalg.norm(p[k, i] - p[k, j]) for k in range(6)
                for i in range(30) for j in range(i))
    assert min_separation({"fleet.position": p}) == pytest.approx(brute, rel=1e-12)
    assert brute == pytest.approx(0.013)
    q = p.copy()
    q[2, 3, 1] = np.nan                         # not a number: said, not skipped
    assert np.isnan(min_separation({"fleet.position": q}))
    big = rng.uniform(0, 300, size=(3, 3000, 3))
    tracemalloc.start()
    try:
        min_separation({"fleet.position": big})
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 30e6, peak     # all pairs of all samples: 3 x 3000^2 x 24 B = 648 MB
