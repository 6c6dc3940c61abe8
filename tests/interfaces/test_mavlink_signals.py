"""The commander (``avblocks run drone_formation --robots mavlink``, a
subprocess) stopped by SIGINT, SIGTERM or SIGKILL mid-mission against the
MAVLink emulator (real UDP): every vehicle ends landed, by the commander's
NAV_LAND (decoded from the emulator's raw log by pymavlink's own parser)
or, after SIGKILL, by its own offboard-loss action; the logs are kept."""

import json
import signal
import subprocess
import sys
import time

import pytest

from avblocks.scenarios.drone_formation import start_positions

from ._mavlink import CMD_LAND, emulator, events, received, wait_landed
from .conftest import env


def _flight_log(path):
    if not path.exists():
        return []
    return [json.loads(s) for s in open(path) if s.strip()]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL],
                         ids=["SIGINT", "SIGTERM", "SIGKILL"])
def test_signal_to_the_commander_lands_every_vehicle_and_keeps_the_log(tmp_path, sig):
    n = 3
    with emulator(tmp_path, n, pose0=start_positions(n, 0.0).tolist()) as (log, spec):
        out = tmp_path / "out"
        cmd = [sys.executable, "-m", "avblocks", "run", "drone_formation", "--set",
               f"agents={n}", "--set", "t_final=60", "--robots", "mavlink",
               "--mavlink-connect", spec, "--out", str(out),
               "--quiet"]
        p = subprocess.Popen(cmd, env=env(), stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
        flog = out / "flight-log.jsonl"
        t_end = time.monotonic() + 90
        while time.monotonic() < t_end and p.poll() is None:
            if any(r.get("phase") == "mission" for r in _flight_log(flog)):
                break
            time.sleep(0.1)
        assert p.poll() is None, p.stdout.read()
        time.sleep(1.5)                                   # mid-mission
        t_sig = time.time()
        p.send_signal(sig)
        rc = p.wait(60)
        text = p.stdout.read()
        landed = wait_landed(log, n, timeout=20)
    assert sorted(landed) == list(range(1, n + 1)), text
    recs = _flight_log(flog)                              # the flight log was kept
    assert any(r.get("phase") == "mission" for r in recs)
    assert sum(r["ev"] == "cmd" for r in recs) > 10
    for sid in range(1, n + 1):
        lands = [r for r, m in received(log, sid, "COMMAND_LONG") if m.command == CMD_LAND]
        loss = events(log, "offboard_loss", sid)
        if sig == signal.SIGKILL:
            # nothing more was sent: the vehicle's own offboard-loss action landed it
            assert not lands
            assert loss and loss[0]["wall"] >= t_sig - 0.1
            assert events(log, "mode", sid)[-1]["to"] == "land"
        else:
            # the commander sent NAV_LAND first: no offboard loss was needed
            assert lands and lands[0]["wall"] >= t_sig - 0.1
            assert not loss
    if sig == signal.SIGKILL:
        assert rc == -signal.SIGKILL
        return
    assert rc == 128 + sig, text
    fs = [r for r in recs if r["ev"] == "failsafe"]
    assert fs and recs[-1]["ev"] == "end"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    assert (out / "results.nc").exists()
