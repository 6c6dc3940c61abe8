"""The same Policy diagram on every engine: the NumPy engine, the live
view and MuJoCo (the ROS 2 emulator is tests/interfaces/test_ros2_policy.py,
the compiled engine tests/rl/test_training.py).

The policy is a small file of known weights (a goal-seeking law in the
Policy's MLP form, ``cmd = clip(2 (goal - p), -1, 1)``), so the tests are
self-contained; a trained file from examples/08 runs the same way. Seed 4
of the navigation scenario: with this law the four agents reach their
goals without touching anything (checked below), so the physics of the
engines is the same up to MuJoCo's vehicles."""

from __future__ import annotations

import os

import numpy as np
import pytest

import avblocks as av
from avblocks.controllers import Policy
from avblocks.scenarios import navigation

SEED = 4


def _policy(path):
    d, _ = navigation.make_diagram()
    obs_dim = d["task"].block.output_ports["obs"].shape[1]
    w = np.zeros((obs_dim, 2))
    w[0, 0] = w[1, 1] = 2.0                     # obs[:, 0:2] is goal - position
    return Policy({"w0": w, "b0": np.zeros(2)}, output="clip").save(path)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    path = _policy(tmp_path_factory.mktemp("pi") / "pi.npz")
    d, sim = navigation.make_diagram(controller=str(path), seed=SEED)
    res = av.simulate(d, **sim, progress=False)
    line, nums = navigation.outcome(res, {})
    assert nums["success"] == 4 and nums["collided"] == 0, line
    return path, res


def test_policy_in_the_live_view_gives_the_same_trajectory(reference):
    """simulate(..., live=...) steps the same engine behind the page: the
    trajectory is bit for bit the plain run's."""
    if not os.environ.get("CI"):
        pytest.importorskip("viser")
    path, ref = reference
    d, sim = navigation.make_diagram(controller=str(path), seed=SEED)
    res = av.simulate(d, **sim, live={"realtime": None, "verbose": False})
    assert res.meta["live"]["ended_by"] == "finished"
    np.testing.assert_array_equal(res["fleet.position"], ref["fleet.position"])
    np.testing.assert_array_equal(res["task.success"], ref["task.success"])


@pytest.mark.mujoco
def test_policy_drives_mujoco_ground_robots_to_the_goals(reference):
    """The fleet of single integrators replaced by MuJoCo ground robots
    (unicycles with a velocity servo, colliding bodies) behind the library's
    off-axis point map (OffAxisPoint, HolonomicToUnicycle, d = 0.1 m): the
    policy, sensors and task are unchanged and read the off-axis points.
    The physics differs (a unicycle turning in place at the start, the
    servo's lag, commands held over MuJoCo's 0.1 s period), so the paths
    agree to a bound, not exactly: the first turn (heading 0 to the goal's
    direction, at most pi / 2 here) moves the point by at most d per radian
    plus the held command's drift over one period (< 1.5 m/s * 0.1 s);
    0.25 m. All four end at their goals without touching anything."""
    try:
        from avblocks.interfaces import mujoco as mj
        mj.import_mujoco()
    except ImportError as e:
        if os.environ.get("CI"):
            raise
        pytest.skip(f"mujoco unavailable: {e}")
    from avblocks.controllers import HolonomicToUnicycle, OffAxisPoint
    path, ref = reference
    L = 0.1

    def vehicles(d, p0):
        scene = mj.Scene(navigation.arena())
        pose0 = np.c_[p0[:, 0] - L, p0[:, 1], np.zeros(len(p0))]   # points at p0
        scene.add_ground_robots("fleet", pose0, radius=0.1)
        phys = d.add(mj.PhysicsWorld(scene, period=0.1), name="fleet")
        pt = d.add(OffAxisPoint(len(p0), d=L), name="point")
        h2u = d.add(HolonomicToUnicycle(len(p0), d=L), name="to_unicycle")
        d.connect(phys.pose, pt.pose)
        d.connect(phys.pose, h2u.pose)
        d.connect(h2u.cmd, phys.cmd)
        return pt.position, h2u.velocity

    d, sim = navigation.make_diagram(controller=str(path), seed=SEED, vehicles=vehicles)
    res = av.simulate(d, **sim, progress=False)
    p = np.asarray(res["point.position"])
    q = np.asarray(ref["fleet.position"])
    np.testing.assert_allclose(p[0], q[0], atol=1e-9)               # same start
    assert np.linalg.norm(p - q, axis=-1).max() < 0.25
    g = np.asarray(ref["goals.y"])[0]
    assert (np.linalg.norm(p[-1] - g, axis=1) < 0.05).all()
    line, nums = navigation.outcome(res, {})
    assert nums["success"] == 4 and nums["collided"] == 0, line
