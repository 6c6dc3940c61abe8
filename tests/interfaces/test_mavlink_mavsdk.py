"""The MAVLink emulator (PX4 flavour) flown by an implementation we did
not write: MAVSDK 4.1 (its C++ library through the ``mavsdk`` package),
in a subprocess, through its own Action and Offboard plugins. The
emulator's own state, sampled here, is the truth: the altitude MAVSDK
asked for (set as MIS_TAKEOFF_ALT with PARAM_SET), the offboard velocity
north, the landing; MAVSDK's parameter reads decode PX4's byte-wise
encoding on their own."""

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from ._mavlink import free_base_port, need_pymavlink
from .conftest import env

HERE = Path(__file__).resolve().parent


def _need_mavsdk():
    try:
        import mavsdk  # noqa: F401
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip("mavsdk not installed (test extra)")


def test_mavsdk_flies_the_emulated_px4_through_action_and_offboard(tmp_path):
    need_pymavlink()
    _need_mavsdk()
    from avblocks.interfaces.mavlink import Emulator
    port, vport = free_base_port(1), free_base_port(1)
    em = Emulator(pose0=[[0.0, 0.0, 0.0]], base_port=port, vehicle_port=vport)
    samples = []
    stop = threading.Event()

    def sample():
        while not stop.is_set():
            samples.append((time.time(), em.x["position"][0].copy(),
                            em.x["velocity"][0].copy(), em.mode[0], bool(em.armed[0])))
            time.sleep(0.05)
    th = threading.Thread(target=em.run, daemon=True)
    th.start()
    sm = threading.Thread(target=sample, daemon=True)
    sm.start()
    alt, v_north, seconds = 1.5, 0.5, 3.0
    try:
        p = subprocess.run([sys.executable, str(HERE / "_mavsdk_flight.py"),
                            f"udpin://127.0.0.1:{port}", str(alt), str(v_north),
                            str(seconds)], env=env(), capture_output=True, text=True,
                           timeout=150)
    finally:
        stop.set()
        em.stop()
        th.join(10)
        sm.join(2)
        em.close()
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-3000:]
    out = json.loads(p.stdout.strip().splitlines()[-1])
    assert "error" not in out, out
    steps = {s["step"]: s for s in out["steps"]}
    assert list(steps) == ["connected", "armed", "takeoff", "up", "offboard", "velocity",
                           "stop", "stopped", "land", "landed", "disarmed"], out
    # MAVSDK decoded the emulated PX4's parameters (INT32 byte-wise) itself
    assert out["COM_OBL_RC_ACT"] == 4 and out["COM_OF_LOSS_T"] == pytest.approx(0.5)
    assert out["takeoff_altitude"] == pytest.approx(alt)
    assert em.params[0]["MIS_TAKEOFF_ALT"] == pytest.approx(alt)   # set by PARAM_SET
    t = np.array([s[0] for s in samples])
    pos = np.array([s[1] for s in samples])
    vel = np.array([s[2] for s in samples])
    # up: at MIS_TAKEOFF_ALT when offboard started, in Hold after takeoff
    k = np.searchsorted(t, steps["offboard"]["wall"])
    assert pos[k, 2] == pytest.approx(alt, abs=0.1)
    modes = [s[3] for s in samples]
    assert "takeoff" in modes and "offboard" in modes and "hold" in modes
    # offboard: north (ENU +y) at the commanded speed, no east or vertical motion
    w = (t > steps["velocity"]["wall"] + 1.0) & (t < steps["stop"]["wall"])
    assert w.sum() > 20
    np.testing.assert_allclose(np.median(vel[w], axis=0), [0.0, v_north, 0.0], atol=0.05)
    i0, i1 = np.searchsorted(t, [steps["velocity"]["wall"], steps["stopped"]["wall"]])
    assert pos[i1, 1] - pos[i0, 1] == pytest.approx(v_north * seconds, rel=0.2)
    # landed and disarmed, as MAVSDK also saw (LandedState.ON_GROUND = 1)
    assert pos[-1, 2] == pytest.approx(0.0, abs=0.03) and not samples[-1][4]
    # (the disarm reaches MAVSDK with a HEARTBEAT, at 1 Hz: the script waits
    # for it after the EXTENDED_SYS_STATE that says "on ground")
    assert steps["landed"]["landed_state"] == 1 and steps["disarmed"]["armed"] is False
    assert [e for e in em.events if e["ev"] == "landed"]
