"""Lab 7 (learning) beyond the shared lab tests: the check's truth is the
library's task, the training glue computes what the task block computes,
the policy travels as text and back bit for bit, the shipped policy is the
reference solution's, and a policy that is not a network the grader can
run is refused by name."""

from __future__ import annotations

import importlib.util
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from avblocks.environment.boxes import boundary_distance
from avblocks.labs import Lab, get, run_checks
from avblocks.labs import lab7_learning as lab7
from avblocks.scenarios import navigation
from avblocks.tasks import NavigationTask

HERE = Path(__file__).resolve().parent
SOLUTION = HERE / "solutions" / "lab7_learning.py"


def _reference():
    spec = importlib.util.spec_from_file_location("lab7_reference", SOLUTION)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8])
def test_the_checks_truth_is_the_library_task(n):
    """observation_truth and reward_truth (scalar loops) against the task
    block's vectorized output, on random states of n agents."""
    rng = np.random.default_rng(n)
    world = navigation.arena()
    task = NavigationTask(n, world, progress=4.0, collision=3.0, proximity=0.7, margin=0.25,
                          goal_bonus=0.3, first_hit=2.0, success_bonus=0.4)
    p = rng.uniform(-1.4, 1.4, (n, 2))
    g = p + rng.normal(scale=0.2, size=(n, 2))
    ranges = rng.uniform(0, 1, (n, 12))
    prev, hit, contact = rng.uniform(0, 2, n), rng.random(n) < 0.5, rng.random(n) < 0.5
    y = task.output(0.0, {"prev": prev, "hit": hit},
                    {"position": p, "goals": g, "ranges": ranges, "contact": contact}, np)
    np.testing.assert_allclose(lab7.observation_truth(p, g, ranges, 1.5, 1.0), y["obs"],
                               atol=1e-12, rtol=0)
    clearance = boundary_distance(p[:, 0:1], p[:, 1:2], task.boxes, task.rest_seg, np)
    prm = lab7.reward_params(progress=4.0, collision=3.0, proximity=0.7, margin=0.25,
                             goal_bonus=0.3, first_hit=2.0, success_bonus=0.4)
    # the task block regularizes its square roots by 1e-12
    np.testing.assert_allclose(lab7.reward_truth(p, g, prev, contact, hit, clearance, prm),
                               y["reward"], atol=1e-9, rtol=0)


def test_the_training_glue_computes_the_task_blocks_numbers():
    """training_task with the reference solution's functions, stepped on the
    NumPy engine: its observation and reward are the task block's."""
    from avblocks import rl
    sol = _reference()
    env = rl.functional(lab7.training_task(sol.observe, sol.reward), backend="numpy")
    assert (env.n, env.obs_dim, env.act_dim) == (3, lab7.obs_size(3, 12), 2)
    state, obs = env.reset(np.array([3, 4], np.uint32))
    rng = np.random.default_rng(0)
    seen = 0
    for _ in range(25):
        a = rng.uniform(-1, 1, (3, 2))
        state, obs, r, done, info = env.step_env(state, a)
        sig = env._signals(state.Y)
        np.testing.assert_allclose(obs, sig["task.obs"], atol=1e-6)       # float32 obs
        np.testing.assert_allclose(r, sig["task.reward"], atol=1e-5)
        seen += int(np.asarray(sig["task.collision"]).any())
    assert seen, "the random walk never touched anything: the contact terms were not tried"


def test_the_policy_travels_as_text_bit_for_bit(tmp_path):
    rng = np.random.default_rng(1)
    w = {"w0": rng.normal(size=(20, 7)), "b0": rng.normal(size=7),
         "w1": rng.normal(size=(7, 2)), "b1": rng.normal(size=2)}
    assert all(np.array_equal(lab7.decode_policy(lab7.encode_policy(w))[k], w[k]) for k in w)
    f = tmp_path / "lab7_learning.py"
    shutil.copyfile(get(7).template, f)
    assert lab7.embed_policy(w, f) == 20 * 7 + 7 + 7 * 2 + 2
    assert lab7.embed_policy(w, f) == 163                      # again: replaced, not added
    text = f.read_text()
    assert text.count('POLICY = """') == 1 and max(map(len, text.splitlines())) <= 100
    ns = {}
    exec(compile(text, str(f), "exec"), ns)                   # our own file: the template
    got = ns["policy"]()
    assert sorted(got) == sorted(w) and all(np.array_equal(got[k], w[k]) for k in w)
    (tmp_path / "bad.py").write_text("x = 1\n")
    with pytest.raises(ValueError, match='POLICY = """'):
        lab7.embed_policy(w, tmp_path / "bad.py")


def test_the_shipped_policy_is_the_reference_solutions():
    """src/avblocks/labs/data/lab7_policy.npz (what the page loads in the
    docs' tests) holds the weights embedded in the reference solution, of
    the size its note says; the reference solution passes the check, so
    both reach the threshold."""
    sol = _reference()
    ref, shipped = sol.policy(), lab7.example_policy()
    assert sorted(ref) == sorted(shipped) == ["b0", "b1", "b2", "w0", "w1", "w2"]
    assert all(np.array_equal(ref[k], shipped[k]) for k in ref)
    note = re.search(r"^# (\d+) parameters, .*?; ([\d.]+)% over the check's (\d+) fixed",
                     SOLUTION.read_text(), re.M)
    assert note and int(note.group(1)) == sum(v.size for v in ref.values())
    assert int(note.group(3)) == lab7.EPISODES
    assert float(note.group(2)) / 100 >= lab7.THRESHOLD


BAD_POLICIES = {
    "keys": ('{"weights": np.zeros((20, 2))}', "returned the keys ['weights'], expected w0, b0"),
    "first": ('{"w0": np.zeros((22, 2)), "b0": np.zeros(2)}',
              "w0 has shape (22, 2) and b0 (2,); expected (20, units)"),
    "nan": ('{"w0": np.full((20, 2), np.nan), "b0": np.zeros(2)}', "holds NaN or inf"),
    "outputs": ('{"w0": np.zeros((20, 3)), "b0": np.zeros(3)}', "the last layer has 3 outputs"),
    "wide": ('{"w0": np.zeros((20, 600)), "b0": np.zeros(600), "w1": np.zeros((600, 2)), '
             '"b1": np.zeros(2)}', "with units <= 512"),
    "list": ('[np.zeros((20, 2)), np.zeros(2)]', "`policy` returned a list"),
}


@pytest.mark.parametrize("kind", sorted(BAD_POLICIES))
def test_a_policy_the_grader_cannot_run_is_refused_by_name(tmp_path, kind):
    body, says = BAD_POLICIES[kind]
    f = tmp_path / f"lab7_{kind}.py"
    f.write_text(SOLUTION.read_text() + f"\n\ndef policy():\n    return {body}\n")
    lab = get(7)
    only = Lab(7, lab.name, lab.title, names=lab.names,
               checks=[c for c in lab.checks if c[0] == "the trained policy on held-out episodes"])
    r = run_checks(only, f)
    assert not r.passed and says in r.checks[0].message, r.checks[0].message


def test_the_students_functions_trace_under_jax():
    """What training needs: the glue with the reference solution's functions
    steps under ``jax.jit`` (the functions trace) to the NumPy engine's
    numbers (float32 against float64)."""
    pytest.importorskip("jax")
    import jax

    from avblocks import rl
    sol = _reference()
    task = lab7.training_task(sol.observe, sol.reward)
    envs = {b: rl.functional(task, backend=b) for b in ("numpy", "jax")}
    key = np.array([5, 6], np.uint32)
    s_np, o_np = envs["numpy"].reset(key)
    s_jx, o_jx = jax.jit(envs["jax"].reset)(key)
    np.testing.assert_allclose(np.asarray(o_jx), o_np, atol=1e-5)
    step = jax.jit(envs["jax"].step_env)
    rng = np.random.default_rng(2)
    for _ in range(5):
        a = rng.uniform(-1, 1, (3, 2))
        s_np, o_np, r_np, _, _ = envs["numpy"].step_env(s_np, a)
        s_jx, o_jx, r_jx, _, _ = step(s_jx, a.astype(np.float32))
        np.testing.assert_allclose(np.asarray(o_jx), o_np, atol=1e-4)
        np.testing.assert_allclose(np.asarray(r_jx), r_np, atol=1e-4)


def test_a_run_late_enough_to_use_up_the_margin_is_flown_again():
    """The emulator check flies a failed run again when the machine did not
    keep real time: a step late by L lets a robot go on SPEED_MAX * L along
    its last command, so a lateness that covers the episode's margin to a
    contact (0.1 m at sqrt(2) m/s: 70.7 ms) is a disturbed run."""
    from avblocks.labs import lab7_learning as L
    assert L.DISTURBED_LATENESS * L.SPEED_MAX == pytest.approx(L.MARGIN, rel=1e-12)
    assert L.DISTURBED_LATENESS == pytest.approx(0.0707107, rel=1e-5)
    # the run seen on a loaded machine: 2 of 60 steps late, the worst 212 ms
    assert L.disturbed(60, 2, 0.212)
    assert not L.disturbed(60, 2, 0.005)         # a quiet machine: a few ms
    assert not L.disturbed(60, 12, 0.05)         # 20 % of the steps late: not yet
    assert L.disturbed(60, 13, 0.0)              # more than 20 %
