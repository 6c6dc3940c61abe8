"""The built-in case-study scenarios, run small: the outcome a researcher checks."""


import numpy as np
import pytest
from scipy.spatial.distance import cdist, pdist

import avblocks as av
from avblocks.cli import main
from avblocks.scenarios import builtin_scenarios


def run(name, **params):
    import importlib
    mod = importlib.import_module(f"avblocks.scenarios.{name}")
    d, sim = mod.make_diagram(**params)
    return mod, av.simulate(d, progress=False, **sim)


@pytest.mark.parametrize("name", ["nest", "formation", "flocking", "swap"])
def test_listed_with_description_and_movie_options(name, capsys):
    assert name in builtin_scenarios()
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert f"\n{name}\n" in f"\n{out}"
    import importlib
    mod = importlib.import_module(f"avblocks.scenarios.{name}")
    assert isinstance(mod.MOVIE, dict)


# --------------------------------------------------------------------- nest
def test_nest_information_reaches_everyone_by_contact():
    mod, res = run("nest", agents=60, t_final=40.0, seed=1)
    inf = np.asarray(res["gossip.informed"])
    pose = np.asarray(res["bees.pose"])
    radius = 1.0
    count = inf.sum(axis=1)
    assert count[0] == 5                                  # the scouts
    assert np.all(np.diff(count) >= 0)                   # monotone
    assert np.all(inf[1:] >= inf[:-1])                   # latched per agent
    assert inf[-1].all()                                  # everyone informed
    t_all = res.t[np.argmax(count == 60)]
    assert 5.0 < t_all < 40.0                             # ~28 s with seed 1
    # against the contact graph of the logged poses: agent j is informed at
    # step k+1 iff it was informed at k or an informed agent was within range
    # at k (no loss; log_every = 1)
    for k in range(len(res.t) - 1):
        dist = cdist(pose[k, :, :2], pose[k, :, :2])
        contact = ((dist <= radius) & inf[k][:, None]).any(axis=0)
        np.testing.assert_array_equal(inf[k + 1], inf[k] | contact, err_msg=f"step {k}")
    # everyone stayed in the hexagonal nest
    r = mod.hexagon_radius(60, 0.5)
    assert np.all(np.abs(pose[..., 1]) <= r * np.sqrt(3) / 2 + 0.5)


# ---------------------------------------------------------------- formation
def test_formation_switches_wedge_column_wedge_without_collision():
    mod, res = run("formation", dt=0.05, log_every=2)
    t = res.t
    mode = np.asarray(res["supervisor.mode"])
    err = np.abs(np.asarray(res["lf.error"])).max(axis=1)        # (T, 2): l, alpha
    pose = np.asarray(res["fleet.pose"])
    # the supervisor's state sequence
    seq = [int(mode[0])] + [int(m) for m in mode[1:][np.diff(mode) != 0]]
    assert [mod.STATES[s] for s in seq] == ["wedge", "column", "wedge"]
    sw = np.flatnonzero(np.diff(mode) != 0) + 1                  # first sample after
    x_in, x_out = mod.switch_points(5, 1.5)
    # (the guard fires at a major step, the mode shows from the next one)
    assert pose[sw[0] - 2, 0, 0] < x_in <= pose[sw[0], 0, 0]
    assert pose[sw[1] - 2, 0, 0] < x_out <= pose[sw[1], 0, 0]
    # converged before each switch and at the end; disturbed after each switch
    for i in (sw[0] - 1, sw[1] - 1, len(t) - 1):
        assert np.all(err[i] < [0.02, 0.02]), (t[i], err[i])
    for i in sw:
        assert err[i + int(2.0 / (t[1] - t[0]))].max() > 0.05
    # the column is formed (followers on the leader's line) before the corridor
    k_in = np.argmax(pose[:, 0, 0] >= mod.CORRIDOR[0] - 1.0)
    assert np.all(np.abs(pose[k_in, :, 1]) < 0.05)
    assert np.all(err[k_in] < 0.02)
    # everyone went through the corridor, nobody touched a wall or another
    assert np.all(pose[-1, :, 0] > mod.CORRIDOR[1] + 3.0)
    assert not np.asarray(res["collision.hit_obstacle"]).any()
    assert not np.asarray(res["collision.hit_agent"]).any()


# ----------------------------------------------------------------- flocking
def test_flocking_aligns_and_keeps_spacing():
    d = 7.0
    mod, res = run("flocking", agents=20, spread=30.0, t_final=30.0, dt=0.04)
    q = np.asarray(res["flock.position"])
    v = np.asarray(res["flock.velocity"])
    order = np.asarray(res["view.order"])
    np.testing.assert_allclose(order, [av.controllers.order_parameter(x) for x in v])
    assert order[0] < 0.5 and order[-1] > 0.95
    dmin = np.array([pdist(x).min() for x in q])
    assert dmin.min() > 0.5 * d                       # no pair ever closer than d / 2
    assert dmin[-1] > 0.7 * d
    # one cohesive flock: every agent has a neighbour within the range r = 1.2 d
    dd = cdist(q[-1], q[-1]) + np.eye(len(q[-1])) * 1e9
    assert dd.min(axis=1).max() < 1.2 * d
    # the flock follows the moving gamma agent
    target = np.array([25.0, 25.0]) + np.array([2.0, 1.0]) * res.t[-1]
    assert np.linalg.norm(q[-1].mean(axis=0) - target) < 1.0
    np.testing.assert_allclose(res["view.pose"][..., :2], q)


# --------------------------------------------------------------------- swap
def test_swap_is_safe_and_everyone_arrives():
    mod, res = run("swap")
    p = np.asarray(res["fleet.position"])
    n = p.shape[1]
    assert n == 20
    dmin = np.array([pdist(x).min() for x in p])
    assert dmin.min() >= 0.6 - 1e-3
    start, goal = mod.circle_swap(n, 5.0, 0.5, 1)
    np.testing.assert_allclose(p[0], start)
    assert np.asarray(res["drive.done"])[-1].all()
    assert np.linalg.norm(p[-1] - goal, axis=1).max() < 0.06
    # they really crossed the middle (not a detour around the circle of
    # radius 5): the joint filter's roundabout passes within 2.1 m of the
    # centre, a ring of 20 agents 0.6 m apart has radius 1.9 m
    assert np.linalg.norm(p, axis=2).min() < 2.5


def test_swap_without_symmetry_breaking_jams_but_stays_safe():
    mod, res = run("swap", agents=8, jitter=0.0, speed_spread=0.0, right_hand=0.0,
                   t_final=10.0)
    p = np.asarray(res["fleet.position"])
    assert min(pdist(x).min() for x in p) >= 0.6 - 1e-3
    assert not np.asarray(res["drive.done"])[-1].any()


def test_swap_at_robotarium_ratio_jams_per_agent_and_completes_by_default(monkeypatch):
    """Circle / safety radius 5.88 (Robotarium's default): the per-agent
    filter leaves two agents stuck, the default (the joint QP, built-in
    ADMM solver, no optional dependency: Clarabel is made unimportable
    here) brings all 20 home, both without ever breaking the safety radius."""
    import sys
    monkeypatch.setitem(sys.modules, "clarabel", None)      # import clarabel fails
    out = {}
    for mode in ("agent", None):
        mod, res = run("swap", safety=0.85, **({"mode": mode} if mode else {}))
        p = np.asarray(res["fleet.position"])
        assert min(pdist(x).min() for x in p) >= 0.85 - 1e-6
        out[mode or "default"] = int(np.asarray(res["drive.done"])[-1].sum())
    assert out == {"agent": 18, "default": 20}


def test_cli_runs_a_case_study(tmp_path):
    rc = main(["run", "swap", "--set", "agents=6", "--set", "t_final=3",
               "--out", str(tmp_path), "--quiet"])
    assert rc == 0
    assert (tmp_path / "swap.png").stat().st_size > 5000
    res = av.Results.load(tmp_path / "results.nc")
    assert res["fleet.position"].shape[1:] == (6, 2)
