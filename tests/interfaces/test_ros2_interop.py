"""Interoperability with an rmw_zenoh implementation nobody here wrote:
zenoh-ros2-sdk (plain Python) as the robot. A Twist published by the
Robots block in rmw_zenoh mode arrives there with the right values, and
the Odometry it publishes arrives in the block with the right pose."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import avblocks as av

from .conftest import _need, env

PEER = str(Path(__file__).with_name("_sdk_peer.py"))


def test_twist_out_and_odometry_in_with_zenoh_ros2_sdk(router, tmp_path):
    _need("zenoh_ros2_sdk")
    from avblocks.interfaces.ros2 import Robots, _msgs
    host, port = router.split("/", 1)[1].rsplit(":", 1)
    out = tmp_path / "sdk.jsonl"
    p = subprocess.Popen([sys.executable, PEER, host, port, str(tmp_path / "msgs"), str(out),
                          _msgs.type_hash(_msgs.TWIST), _msgs.type_hash(_msgs.ODOMETRY)],
                         env={**env(), "ZENOH_ROS2_SDK_CACHE": str(tmp_path / "cache")},
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert p.stdout.readline().strip() == "ready", p.stdout.read()
        d = av.Diagram()
        c = d.add(av.blocks.Constant(np.array([[0.15, -0.35]])), name="c")
        f = d.add(Robots(["tb1"], transport="rmw_zenoh", router=router, wait=10.0),
                  name="fleet")
        d.connect(c.y, f.cmd)
        res = av.simulate(d, t_final=0.5, dt=0.05, realtime=1.0,
                          log=["fleet.pose", "fleet.fresh"])
        time.sleep(0.3)
    finally:
        p.terminate()
        p.wait(10)
    # the SDK's odometry, decoded by the block: the pose the peer published
    assert res["fleet.pose"][-1, 0] == pytest.approx([1.25, -0.5, 0.75], abs=1e-12)
    assert res["fleet.fresh"][-1, 0]
    # the block's twists, decoded by the SDK
    got = [json.loads(s) for s in out.read_text().splitlines()]
    moving = [g for g in got if g["v"] != 0]
    assert len(moving) >= 5
    assert all(g["v"] == 0.15 and g["w"] == -0.35 and g["vy"] == 0 for g in moving)
    assert got[-1]["v"] == 0 and got[-1]["w"] == 0          # stopped at the end
