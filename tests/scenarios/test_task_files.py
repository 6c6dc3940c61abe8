"""The learning-task case studies (pursuit, spread, navigation) as scenario
files: the file runs to the numbers the Python-only case study gave before
it had a file, a trained policy runs from the file as from the module, and
the task blocks named from a file compute their documented equations."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import avblocks as av
from avblocks.cli import main
from avblocks.scenarios import builtin_scenarios, load_scenario

#: summary.json numbers of `avblocks run <name> [--set ...]` on main at
#: cf15bf0, when the three were Python-only case studies (the truth the
#: files must reproduce; measured before the files existed).
BEFORE = {
    ("pursuit", ()): ("3 pursuers caught the evader at 2 s",
                      {"capture_s": 2.0, "closest_m": 0.0012807932096073511}),
    ("spread", ()): ("all 3 landmarks covered at 1 s, final reward -0.000",
                     {"covered_s": 1.0, "final_reward": -5.595456662281804e-05,
                      "success": True}),
    ("navigation", ()): ("3 of 4 agents at their goals without collision at 6 s "
                         "(0 touched something)", {"success": 3, "agents": 4, "collided": 0}),
    ("pursuit", ("t_final=3", "seed=2", "agents=4")):
        ("4 pursuers caught the evader at 1.1 s",
         {"capture_s": 1.1, "closest_m": 0.005657448345507004}),
    ("spread", ("t_final=3", "seed=2", "agents=4")):
        ("all 4 landmarks covered at 1.3 s, final reward -0.006",
         {"covered_s": 1.3, "final_reward": -0.005929805370846241, "success": True}),
    ("navigation", ("t_final=3", "seed=2", "agents=3")):
        ("1 of 3 agents at their goals without collision at 3 s (2 touched something)",
         {"success": 1, "agents": 3, "collided": 2}),
}


def _summary(target, out, sets=()):
    argv = ["run", str(target), "--quiet", "--out", str(out)]
    for s in sets:
        argv += ["--set", s]
    assert main(argv) == 0
    return json.loads((out / "summary.json").read_text())


@pytest.mark.parametrize("name, sets", list(BEFORE))
def test_the_file_runs_to_the_numbers_the_python_case_study_gave(name, sets, tmp_path):
    assert builtin_scenarios()[name].suffix == ".yaml"        # the file is what runs
    line, numbers = BEFORE[(name, sets)]
    got = _summary(name, tmp_path / "yaml", sets)
    assert got["status"] == "complete"
    assert got["outcome"] == line
    assert got["numbers"] == numbers                          # exactly, every digit
    # and the module, run as a file, still gives them
    module = builtin_scenarios()[name].with_suffix(".py")
    py = _summary(module, tmp_path / "py", sets)
    assert py["numbers"] == numbers and py["outcome"] == line


def _policy(path, obs_dim, cols):
    """A linear policy: cmd = clip(2 * obs[:, cols])."""
    w = np.zeros((obs_dim, 2))
    w[cols[0], 0] = w[cols[1], 1] = 2.0
    return av.controllers.Policy({"w0": w, "b0": np.zeros(2)}, output="clip").save(path)


@pytest.mark.parametrize("name, agents, obs_dim, cols", [
    ("pursuit", 3, 4 + 2 * 2, (2, 3)),          # the evader relative to the pursuer
    ("spread", 3, 2 + 6 + 4, (2, 3)),           # the first landmark relative to the agent
    ("navigation", 4, 4 + 12 + 6, (0, 1)),      # the goal relative to the agent
])
def test_a_trained_policy_runs_from_the_file_as_from_the_module(name, agents, obs_dim,
                                                                 cols, tmp_path):
    import importlib

    from avblocks.scenarios.targets import load_any
    path = str(_policy(tmp_path / "pi.npz", obs_dim, cols))
    sets = {"controller": path, "t_final": 2.0, "seed": 3}
    d1, s1, *_ = load_any(name, sets)
    r1 = av.simulate(d1, progress=False, **s1)
    mod = importlib.import_module(f"avblocks.scenarios.{name}")
    d2, s2 = mod.make_diagram(**sets)
    r2 = av.simulate(d2, progress=False, **s2)
    pos = "pursuers.position" if name == "pursuit" else "fleet.position"
    np.testing.assert_array_equal(np.asarray(r1[pos]), np.asarray(r2[pos]))
    # the policy drove them (not the scripted law): the scripted run differs
    d3, s3, *_ = load_any(name, {"t_final": 2.0, "seed": 3})
    r3 = av.simulate(d3, progress=False, **s3)
    assert not np.allclose(np.asarray(r1[pos])[-1], np.asarray(r3[pos])[-1])


def test_flee_and_chase_follow_their_equations():
    from avblocks.tasks import Chase, Flee
    p = np.array([[0.0, 0.0], [2.0, 0.0]])
    ex, ey = 1.0, 1.45
    e = np.array([[ex, ey]])
    half, speed = 1.5, 0.7
    # by hand: away = sum (e - p_i) / (|e - p_i|^2 + 1e-6), normalised; the
    # evader is 0.05 from the top wall (margin 0.45): push y = -(0.45 - 0.05) / 0.45
    ax = ay = 0.0
    for px, py in p:
        dx, dy = ex - px, ey - py
        r2 = dx * dx + dy * dy + 1e-6
        ax, ay = ax + dx / r2, ay + dy / r2
    na = math.sqrt(ax * ax + ay * ay + 1e-12)
    m = 0.3 * half
    push_x = 0.0                                    # 0.5 from the side walls
    push_y = -(m - (half - ey)) / m
    vx, vy = ax / na + 2 * push_x, ay / na + 2 * push_y
    nv = math.sqrt(vx * vx + vy * vy + 1e-12)
    got = Flee(2, half=half, speed=speed).output(0.0, {}, {"pursuers": p, "evader": e},
                                                 np)["velocity"]
    np.testing.assert_allclose(got, [[speed * vx / nv, speed * vy / nv]], rtol=1e-12)
    assert got[0, 1] < 0                   # the wall turned it down, away from y = half
    c = Chase(2).output(0.0, {}, {"pursuers": p, "evader": e}, np)["cmd"]
    r = math.hypot(1.0, ey)
    np.testing.assert_allclose(c, [[1 / r, ey / r], [-1 / r, ey / r]], rtol=1e-9)


def test_assign_landmarks_is_the_least_total_distance_matching():
    from itertools import permutations

    from avblocks.tasks import assign_landmarks
    rng = np.random.default_rng(0)
    p, lm = rng.uniform(-1, 1, (5, 2)), rng.uniform(-1, 1, (5, 2))
    got = assign_landmarks(p, lm)
    best = min(permutations(range(5)),
               key=lambda s: sum(np.linalg.norm(p[i] - lm[j]) for i, j in enumerate(s)))
    np.testing.assert_array_equal(got, lm[list(best)])       # brute force over 120


def test_task_command_passes_the_script_or_scales_the_policy(tmp_path):
    from avblocks.controllers import Policy
    from avblocks.tasks import TaskCommand
    obs = np.array([[0.2, -0.3, 5.0], [1.0, 0.1, 0.0]])
    scripted = np.array([[0.5, 0.5], [-1.0, 2.0]])
    c = TaskCommand(2)
    np.testing.assert_array_equal(
        c.output(0.0, {}, {"scripted": scripted, "obs": obs}, np)["velocity"], scripted)
    w = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]])
    path = Policy({"w0": w, "b0": np.zeros(2)}, output="clip").save(tmp_path / "p.npz")
    c = TaskCommand(2, policy=str(path), speed=1.5)
    c.configure({"obs": type("S", (), {"shape": (2, 3)})()})
    got = c.output(0.0, {}, {"scripted": scripted, "obs": obs}, np)["velocity"]
    np.testing.assert_allclose(got, 1.5 * np.clip(obs[:, :2], -1, 1))
    with pytest.raises(av.AvError, match="policy"):
        TaskCommand(2, policy=str(tmp_path / "missing.npz"))


@pytest.mark.parametrize("name, entry, bad, match", [
    ("pursuit", "position0", {"pursuit_starts": {"agents": 3, "half": 1.5, "seed": 1,
                                                 "which": "hunter"}}, "which"),
    ("spread", "position0", {"spread_starts": {"agents": -2, "half": 1.0, "seed": 1}},
     "agents"),
    ("navigation", "position0", {"navigation_starts": {"agents": 2, "seed": "x"}}, "seed"),
])
def test_a_bad_generator_argument_names_the_entry(name, entry, bad, match):
    sc = load_scenario(name)
    block = "pursuers" if name == "pursuit" else "fleet"
    sc.data["blocks"][block][entry] = bad
    with pytest.raises(av.ScenarioError, match=match) as e:
        sc.build()
    assert f"blocks.{block}.{entry}" in str(e.value)


def test_the_matching_generator_refuses_more_agents_than_it_can_match_in_seconds(tmp_path):
    """The Hungarian matching takes O(N^3) time, which the memory budget
    does not bound (4,000 agents: 4.5 s; a fuzzed file once asked for
    thousands): a file's ``spread_targets`` stops at MAX_MATCHED, before
    drawing anything, and the error names the entry, the limit and N."""
    from avblocks.scenarios.spread import MAX_MATCHED
    sc = load_scenario("spread")
    sc.data["blocks"]["drive"]["waypoints"] = {
        "spread_targets": {"agents": MAX_MATCHED + 1, "half": 1.0, "seed": 1}}
    with pytest.raises(av.ScenarioError, match="agents") as e:
        sc.build()
    msg = str(e.value)
    assert "blocks.drive.waypoints" in msg and f"<= {MAX_MATCHED:,}" in msg
    assert f"{MAX_MATCHED + 1:,}" in msg
    out = tmp_path / "out"
    assert main(["run", "spread", "--set", f"agents={MAX_MATCHED + 1}", "--out",
                 str(out)]) == 2


def test_the_policy_file_is_named_in_the_error_when_it_is_missing(tmp_path):
    with pytest.raises(av.ScenarioError, match="policy") as e:
        load_scenario("navigation").with_overrides(
            {"controller": str(tmp_path / "none.npz")}).build()
    assert "blocks.command" in str(e.value)


@pytest.mark.parametrize("name", ["pursuit", "spread", "navigation"])
def test_the_file_compiles_to_the_numpy_runs_numbers(name, tmp_path):
    """`avblocks run NAME --backend jax` of the file: the NumPy run's outcome
    (capture time, cover time, agents at their goals) and numbers (floats
    within 1e-6 relative: float64 on both, different operation order)."""
    pytest.importorskip("jax")
    sets = ("t_final=3", "seed=2")
    a = _summary(name, tmp_path / "np", sets)
    argv = ["run", name, "--backend", "jax", "--quiet", "--out", str(tmp_path / "jax")]
    for s in sets:
        argv += ["--set", s]
    assert main(argv) == 0
    b = json.loads((tmp_path / "jax" / "summary.json").read_text())
    assert b["outcome"] == a["outcome"]
    for k, v in a["numbers"].items():
        if isinstance(v, float):
            assert b["numbers"][k] == pytest.approx(v, rel=1e-6, abs=1e-9), k
        else:
            assert b["numbers"][k] == v, k
