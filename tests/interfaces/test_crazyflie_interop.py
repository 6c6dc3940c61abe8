"""The Crazyflies block against a Crazyswarm2-server stand-in written with
zenoh-ros2-sdk (``_cf_sdk_peer.py``, a subprocess): the SDK computes its
own type hashes from the interface texts and decodes what arrives, so the
set-points and service calls checked here went through an rmw_zenoh
implementation nobody here wrote, over a real Zenoh router on loopback."""

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

PEER = str(Path(__file__).with_name("_cf_sdk_peer.py"))
START = (0.25, -0.5, 0.0)
V = (0.1, -0.05, 0.02)


def _peer(router, tmp_path):
    host, port = router.split("/", 1)[1].rsplit(":", 1)
    out = tmp_path / "peer.jsonl"
    p = subprocess.Popen([sys.executable, PEER, host, port, str(tmp_path / "msgs"), str(out)],
                         env={**env(), "ZENOH_ROS2_SDK_CACHE": str(tmp_path / "cache")},
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    line = p.stdout.readline().strip()
    if line != "ready":
        p.kill()
        raise AssertionError(f"peer did not start: {line} {p.stdout.read()}")
    return p, out


@pytest.mark.parametrize("setpoint", ["full_state", "velocity"])
def test_setpoints_and_services_decoded_by_zenoh_ros2_sdk(router, tmp_path, setpoint):
    _need("zenoh_ros2_sdk")
    from avblocks.interfaces.crazyflie import Crazyflies
    p, out = _peer(router, tmp_path)
    flight = tmp_path / "flight.jsonl"
    try:
        d = av.Diagram()
        c = d.add(av.blocks.Constant(np.array([V])), name="c")
        f = d.add(Crazyflies(["cf1"], router, setpoint=setpoint, takeoff_height=0.5,
                             land_duration=1.0, log=str(flight), wait=10.0), name="fleet")
        d.connect(c.y, f.velocity)
        res = av.simulate(d, t_final=1.0, dt=0.05, realtime=1.0, log=["fleet.position"],
                          progress=False)
        time.sleep(0.3)
    finally:
        p.terminate()
        p.wait(10)
    got = [json.loads(s) for s in out.read_text().splitlines()]
    ev = {k: [g for g in got if g["ev"] == k] for k in
          ("takeoff", "land", "notify_setpoints_stop", "full_state", "velocity")}
    # services: one takeoff to start z + 0.5 m at the default mean climb of 0.3 m/s,
    # one notification, one land to 0.03 m (Crazyswarm2's examples; a float32 on
    # the wire) in 1 s; group mask 0 (all)
    (tk,), (ld,), (nt,) = ev["takeoff"], ev["land"], ev["notify_setpoints_stop"]
    assert tk["height"] == 0.5 and tk["group_mask"] == 0
    assert tk["duration"] == pytest.approx(0.5 / 0.3, abs=1e-9)
    assert ld["height"] == float(np.float32(0.03))
    assert ld["duration"] == pytest.approx(1.0, abs=1e-9)
    assert nt["remain_valid_millisecs"] == 100 and ld["group_mask"] == nt["group_mask"] == 0
    sp = ev[setpoint]
    other = ev["velocity" if setpoint == "full_state" else "full_state"]
    assert other == []
    # order (Crazyswarm2's notifySetpointsStop contract): takeoff, the set-points,
    # the notification, then land; no set-point after the notification. The
    # peer's subscriber and service callbacks run on Zenoh's threads, so its
    # arrival stamps of two messages a few ms apart may be out of order on a
    # loaded machine (CI saw the last set-point logged 6 ms after the
    # notification): each set-point's own stamp, the sender's clock when it
    # was put, must precede the notification's arrival
    assert tk["wall"] < sp[0]["wall"] and nt["wall"] <= ld["wall"]
    assert max(s["stamp"] for s in sp) < nt["wall"], (sp[-1], nt)
    # the diagram's commands, streamed by the sender at 50 Hz (its default): the
    # values the flight log says were sent, at stamps 20 ms apart
    cmds = [json.loads(s) for s in flight.read_text().splitlines()]
    cmds = [c for c in cmds if c["ev"] == "cmd"]
    assert len(cmds) == 21                      # t = 0, 0.05, ..., 1.0
    assert all(c["v"][0] == list(V) for c in cmds)
    assert all(s["vel"] == list(V) for s in sp)
    stamps = np.array([s["stamp"] for s in sp])
    gaps = np.diff(stamps)
    assert np.median(gaps) == pytest.approx(0.02, abs=0.002)
    assert len(sp) == pytest.approx((stamps[-1] - stamps[0]) / 0.02 + 1, rel=0.1)
    if setpoint == "velocity":
        assert all(s["yaw_rate"] == 0.0 for s in sp)
    else:
        pos = np.array([s["pos"] for s in sp])
        # the reference starts at the pose the peer published after the takeoff ...
        assert pos[0] == pytest.approx([START[0], START[1], 0.5], abs=1e-12)
        # ... and moves along V, each step V times the time since the last set-point
        steps = np.diff(pos, axis=0) / np.array(V)
        assert np.allclose(steps, steps[:, :1], rtol=1e-9, atol=1e-12)
        assert np.abs(steps[:, 0] - gaps).max() < 0.002
        # the yaw held: the vehicle's (the peer's pose has no rotation)
        assert all(s["acc"] == [0.0, 0.0, 0.0] and s["quat"] == [1.0, 0.0, 0.0, 0.0]
                   for s in sp)
    # the block's output: the pose the peer published
    assert res["fleet.position"][0, 0] == pytest.approx([START[0], START[1], 0.5], abs=1e-12)
