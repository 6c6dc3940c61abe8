"""A drone flight and its simulation in one Foxglove layout: the
drone_formation case study flown for a few seconds on five emulated PX4
vehicles over MAVLink/UDP (``avblocks mavlink emulate``, a second process
on loopback, reached as PX4 SITL is: the vehicles send from their own
ports to the commander's, ``udpin:127.0.0.1:BASE+``; they stand on the
scenario's start positions, which pre-flight checks), exported with
``avblocks export RUN --mcap`` next to the same case study simulated,
both read back independently of the writer. The set-points must be those
of the flight log (read here with ``json``), the telemetry the fleet block
logged, the events in order, and the two files on one clock."""

from __future__ import annotations

import json
import os
import random
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import avblocks as av

from ._read import need_readers, read

pytestmark = pytest.mark.slow

SRC = str(Path(__file__).resolve().parents[2] / "src")


def _env():
    e = dict(os.environ)
    e["PYTHONPATH"] = SRC + os.pathsep + e.get("PYTHONPATH", "")
    e["MPLBACKEND"] = "Agg"
    return e


def _free_ports(n):
    for _ in range(200):
        p = random.randint(20000, 60000 - n)
        socks = []
        try:
            for k in range(n):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(s)
                s.bind(("127.0.0.1", p + k))
            return p
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError("no free UDP ports")


def _run(args, timeout=300):
    p = subprocess.run([sys.executable, "-m", "avblocks", *args], env=_env(),
                       capture_output=True, text=True, timeout=timeout)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    return p.stdout


def test_a_flight_and_its_simulation_export_side_by_side(tmp_path):
    need_readers()
    if os.environ.get("CI"):
        import foxglove  # noqa: F401
        import pymavlink  # noqa: F401
    else:
        pytest.importorskip("foxglove")
        pytest.importorskip("pymavlink")
    from avblocks.scenarios import drone_formation as df
    n, t_final = 5, 2.0
    base = vport = _free_ports(n)      # the commander's (PX4: 14540+i) ...
    while abs(vport - base) < n:        # ... and the vehicles' own (14580+i)
        vport = _free_ports(n)
    elog = tmp_path / "emulator.jsonl"
    pose0 = df.start_positions(n, 0.0).tolist()
    emu = subprocess.Popen([sys.executable, "-m", "avblocks", "mavlink", "emulate", "--n",
                            str(n), "--base-port", str(base), "--vehicle-port", str(vport),
                            "--pose0", json.dumps(pose0),
                            "--log", str(elog)], env=_env(), stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True)
    try:
        t_end = time.monotonic() + 30
        while not (elog.exists() and elog.stat().st_size) and time.monotonic() < t_end:
            assert emu.poll() is None, emu.stdout.read()
            time.sleep(0.05)
        _run(["run", "drone_formation", "--t-final", str(t_final), "--quiet", "--out",
              str(tmp_path / "fly"), "--robots", "mavlink", "--mavlink-connect",
              f"udpin:127.0.0.1:{base}+"])
    finally:
        emu.terminate()
        try:
            emu.wait(10)
        except subprocess.TimeoutExpired:  # pragma: no cover
            emu.kill()
    _run(["run", "drone_formation", "--t-final", str(t_final), "--quiet", "--out",
          str(tmp_path / "sim")])
    assert "flight.mcap" in _run(["export", str(tmp_path / "fly"), "--mcap"])
    assert "sim.mcap" in _run(["export", str(tmp_path / "sim"), "--mcap"])
    fly, _s, meta = read(tmp_path / "fly" / "flight.mcap")
    sim, _s2, _m2 = read(tmp_path / "sim" / "sim.mcap")
    assert meta["avblocks"]["prefix"] == "flight"
    # the set-points: exactly the flight log's, at their simulated times
    recs = [json.loads(s) for s in open(tmp_path / "fly" / "flight-log.jsonl")]
    cmds = [r for r in recs if r["ev"] == "cmd"]
    sp = fly["/flight/setpoint"]
    assert len(sp) == len(cmds) >= 10
    assert [m.log_time for m in sp] == [round(r["t"] * 1e9) for r in cmds]
    np.testing.assert_array_equal([[[a["x"], a["y"], a["z"]] for a in m.value["agents"]]
                                   for m in sp], [r["v"] for r in cmds])
    arrows = fly["/flight/setpoint_arrows"]
    assert len(arrows) == len(cmds) and arrows[-1].value.entities[0].arrows
    # the telemetry: the fleet block's logged positions, on the flight's frames
    res = av.Results.load(tmp_path / "fly" / "results.nc")
    pos = res["fleet.position"]
    tf = fly["/flight/tf"]
    assert len(tf) == len(res.t)
    for m, p in zip(tf, pos):
        trs = [tr for tr in m.value.transforms if tr.child_frame_id.startswith("flight/fleet/")]
        assert [tr.child_frame_id for tr in trs] == [f"flight/fleet/{i}" for i in range(n)]
        np.testing.assert_allclose([[tr.translation.x, tr.translation.y, tr.translation.z]
                                    for tr in trs], p, atol=1e-12)
    (bodies,) = fly["/flight/bodies"]
    assert [e.texts[0].text for e in bodies.value.entities
            if e.frame_id.startswith("flight/fleet/")] == [f"uav{i + 1}" for i in range(n)]
    # the events, in order; those before the mission placed at t = 0 and dated
    text = [m.value.message for m in fly["/flight/log"]]
    phases = [s.split('phase="')[1].split('"')[0] for s in text if 'phase: phase="' in s]
    assert phases == ["preflight", "takeoff", "mission", "land", "landed"]
    assert any(s.startswith("[t = -") and "takeoff" in s for s in text)
    # one clock: both files start at 0 on the same grid, the same signals
    assert [m.log_time for m in sim["/sim/tf"]] == [m.log_time for m in tf]
    assert tf[0].log_time == 0
    sig = {t.split("/signals/")[1] for t in sim if "/signals/" in t}
    assert sig == {t.split("/signals/")[1] for t in fly if "/signals/" in t}
    assert "fleet.position" in sig
