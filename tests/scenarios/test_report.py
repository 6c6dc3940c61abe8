"""What `avblocks run` reports: each scenario's outcome line, its numbers in
summary.json (checked against the saved results), its own figures, movies
under --out, and bad movie names refused before simulating."""

import json

import numpy as np
import pytest
from scipy.spatial.distance import pdist

import avblocks as av
from avblocks.cli import main


def run_cli(tmp_path, *args):
    rc = main(["run", *args, "--out", str(tmp_path), "--quiet"])
    assert rc == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    res = av.Results.load(tmp_path / "results.nc")
    return summary, res


def closest(p):
    return min(pdist(x[:, :2]).min() for x in np.asarray(p))


def test_nest_outcome_numbers_match_the_results(tmp_path, capsys):
    s, res = run_cli(tmp_path, "nest", "--set", "agents=60", "--set", "t_final=40")
    inf = np.asarray(res["gossip.informed"])
    t_all = res.t[np.argmax(inf.all(axis=1))]
    assert inf[-1].all()
    assert s["numbers"]["all_informed_at_s"] == pytest.approx(t_all)
    assert s["outcome"].startswith(f"all 60 informed at {t_all:.3g} s")
    assert f"outcome       all 60 informed at {t_all:.3g} s" in capsys.readouterr().out
    assert (tmp_path / "nest.png").stat().st_size > 20000
    assert str(tmp_path / "nest.png") in s["files"]


def test_swap_outcome_numbers_match_the_results(tmp_path):
    s, res = run_cli(tmp_path, "swap", "--set", "agents=8", "--set", "t_final=20")
    d = closest(res["fleet.position"])
    assert s["numbers"]["closest_approach_m"] == pytest.approx(d, rel=1e-12)
    assert d >= 0.6 - 1e-3
    done = np.asarray(res["drive.done"])
    assert s["numbers"]["all_at_goal_s"] == pytest.approx(res.t[np.argmax(done.all(1))])
    assert f"closest approach {d:.3f} m" in s["outcome"]


def test_formation_outcome_states_and_errors(tmp_path):
    s, res = run_cli(tmp_path, "formation", "--set", "dt=0.05", "--set", "log_every=2")
    assert s["numbers"]["states"] == ["wedge", "column", "wedge"]
    assert max(s["numbers"]["formation_error_before_switch_m"]) < 0.02
    assert s["numbers"]["closest_approach_m"] == pytest.approx(closest(res["fleet.pose"]))
    assert "wedge -> column -> wedge" in s["outcome"] and "no contact" in s["outcome"]


def test_flocking_outcome(tmp_path):
    s, res = run_cli(tmp_path, "flocking", "--set", "agents=20", "--set", "t_final=20")
    v = np.asarray(res["flock.velocity"])
    order = np.linalg.norm(v.sum(axis=1), axis=1) / np.linalg.norm(v, axis=2).sum(axis=1)
    assert s["numbers"]["order_end"] == pytest.approx(order[-1])
    assert s["numbers"]["closest_approach_m"] == pytest.approx(
        closest(res["flock.position"]))


def test_yaml_outcome_and_figures(tmp_path):
    s, res = run_cli(tmp_path, "waypoints", "--set", "agents=5")
    done = np.asarray(res["drive.done"])
    assert done[-1].all()
    t_all = res.t[np.argmax(done.all(axis=1))]
    assert s["outcome"] == f"all 5 reached their last waypoint at {t_all:.3g} s"
    assert (tmp_path / "waypoints.png").is_file() and (tmp_path / "done.png").is_file()


BAD = """
name: tiny
blocks:
  fleet: {type: vehicles.Unicycle, pose0: {zeros: {shape: [2, 3]}}}
  c: {type: blocks.Constant, value: {tile: {value: [1.0, 0.0], n: 2}}}
wires: [[c.y, fleet.cmd]]
simulation: {t_final: 1.0, dt: 0.1}
"""


@pytest.mark.parametrize("extra, match", [
    ("outcome: [{metric: all_tru, signal: c.y}]", "did you mean 'all_true'"),
    ("figures: [{plot: trajectory, file: a.png}]", "did you mean 'trajectories'"),
    ("figures: [{plot: trajectories}]", "needs a 'file'"),
])
def test_bad_outcome_or_figures_are_refused_before_running(tmp_path, extra, match):
    p = tmp_path / "s.yaml"
    p.write_text(BAD + extra + "\n")
    from avblocks.cli import load_any
    with pytest.raises(av.ScenarioError, match=match):
        load_any(str(p), {})


def test_movie_lands_under_out_and_bad_suffix_fails_first(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc = main(["run", "waypoints", "--set", "agents=3", "--set", "simulation.t_final=4",
               "--out", "o", "--movie", "m.gif", "--quiet"])
    assert rc == 0
    assert (tmp_path / "o" / "m.gif").is_file() and not (tmp_path / "m.gif").exists()
    rc = main(["run", "waypoints", "--out", "p", "--movie", "m.avi2", "--quiet"])
    assert rc == 2
    assert not (tmp_path / "p" / "results.nc").exists()     # refused before simulating


def test_gif_of_60_s_15_agents_is_small(tmp_path):
    from PIL import Image

    from avblocks.scenarios import load_scenario
    d, sim = load_scenario("waypoints").build()
    res = av.simulate(d, progress=False, **sim)
    assert res.t[-1] == pytest.approx(60.0) and res["fleet.pose"].shape[1] == 15
    path = av.viz.save_movie(res, tmp_path / "w.gif", color="drive.done", title="w")
    assert path.stat().st_size < 2 * 2**20
    im = Image.open(path)
    assert im.size == (360, 360) and 100 <= im.n_frames <= 200
    # plays the 60 s in at most ~20 s
    assert im.n_frames * im.info["duration"] / 1000 <= 21
