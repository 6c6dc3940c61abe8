"""A Policy block on (emulated) robots: ``avblocks run navigation --set
controller=policy.npz --robots r1,...`` swaps the single integrators for the
ROS 2 robots block and nothing else; the policy reads the observation the
task block computes from the robots' reported positions. The emulator and
the run are subprocesses over real Zenoh on loopback, 4x faster than the
wall clock. The policy here is a small file of known weights (a linear
goal-seeking law in the Policy's MLP form) so the test is self-contained;
a trained file from examples/08 runs the same way."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

import avblocks as av
from avblocks.controllers import Policy
from avblocks.core.results import Results
from avblocks.scenarios import navigation

from .conftest import commands, emulator, env, read_log, wait_for_stop

SCALE = 4.0
NAMES = "r1,r2,r3,r4"


def _policy(path):
    obs_dim = 4 + 12 + 2 * 3
    w = np.zeros((obs_dim, 2))
    w[0, 0] = w[1, 1] = 2.0                     # cmd = clip(2 * (goal - p))
    return Policy({"w0": w, "b0": np.zeros(2)}, output="clip").save(path)


def test_policy_navigates_emulated_robots_like_the_simulation(router, tmp_path):
    path = _policy(tmp_path / "pi.npz")
    d, sim = navigation.make_diagram(controller=str(path), seed=3)
    p0 = d["fleet"].block.initial_state()["position"]
    pose0 = json.dumps([[float(x), float(y), 0.0] for x, y in p0])
    out = tmp_path / "out"
    with emulator(router, NAMES, tmp_path, "--model", "holonomic2d", "--pose0", pose0,
                  "--time-scale", SCALE) as log:
        p = subprocess.run(
            [sys.executable, "-m", "avblocks", "run", "navigation", "--robots", NAMES,
             "--router", router, "--set", f"controller={path}", "--set", "seed=3",
             "--t-final", "4", "--realtime", str(SCALE), "--out", str(out), "--quiet"],
            env=env(), capture_output=True, text=True, timeout=120)
        assert p.returncode == 0, p.stderr
        wait_for_stop(log, NAMES.split(","))
        recs = read_log(log)
    res = Results.load(out / "results.nc")
    sim["t_final"] = 4.0
    ref = av.simulate(d, **sim)
    goals = np.asarray(ref["goals.y"])[0]
    # the same policy on robots ends where the simulation ends (network and
    # pacing delays of a few 10 ms at 1 m/s: a few cm)
    err = np.linalg.norm(np.asarray(res["fleet.position"])[-1]
                         - np.asarray(ref["fleet.position"])[-1], axis=1)
    assert err.max() < 0.1, err
    # they moved towards their goals, and every robot got the final stop
    d0 = np.linalg.norm(p0 - goals, axis=1)
    d1 = np.linalg.norm(np.asarray(res["fleet.position"])[-1] - goals, axis=1)
    assert (d1 < d0 - 0.3).all()
    for r in NAMES.split(","):
        last = commands(recs, r)[-1]
        assert last["v"] == 0.0
