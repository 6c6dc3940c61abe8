"""The three ``... emulate`` commands share one foreground runner
(``interfaces._emulator.run_emulator``): each prints its banner, runs until
SIGTERM, ends its run loop (the log's last record is the run's ``end``
where the emulator writes one), closes and exits 0. Real subprocesses, real
middleware (UDP for MAVLink, a Zenoh router for the others)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ._mavlink import free_base_port, need_pymavlink
from .conftest import env


def _started(p, log, timeout=30):
    t_end = time.monotonic() + timeout
    while not (log.exists() and log.stat().st_size) and time.monotonic() < t_end:
        if p.poll() is not None:
            raise RuntimeError(f"emulator exited: {p.stdout.read()}")
        time.sleep(0.05)
    assert log.exists() and log.stat().st_size, "the emulator wrote no log"


def _sigterm_ends_it(cmd, log, banner, end_record):
    p = subprocess.Popen([sys.executable, "-m", "avblocks", *cmd, "--log", str(log)],
                         env=env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True)
    try:
        _started(p, log)
        time.sleep(0.3)
        p.send_signal(signal.SIGTERM)
        rc = p.wait(20)
        out = p.stdout.read()
    finally:
        if p.poll() is None:  # pragma: no cover - only when the test failed
            p.kill()
            p.wait(10)
    assert rc == 0, out
    assert out.splitlines()[0] == banner, out
    recs = [json.loads(line) for line in Path(log).read_text().splitlines() if line.strip()]
    if end_record:
        assert recs[-1]["ev"] == "end", recs[-3:]


def test_mavlink_emulate_stops_on_sigterm(tmp_path):
    need_pymavlink()
    base, vport = free_base_port(2), free_base_port(2)
    _sigterm_ends_it(["mavlink", "emulate", "--n", "2", "--base-port", str(base),
                      "--vehicle-port", str(vport)],
                     tmp_path / "mav.jsonl",
                     f"emulating 2 px4 vehicle(s) on udp 127.0.0.1:{base}..{base + 1} "
                     f"(connect udpin:127.0.0.1:{base}+; the vehicles send from "
                     f"{vport}..{vport + 1})", end_record=True)


def test_robots_emulate_stops_on_sigterm(router, tmp_path):
    _sigterm_ends_it(["robots", "emulate", "--names", "tb1,tb2", "--router", router],
                     tmp_path / "ros.jsonl",
                     f"emulating tb1,tb2 (unicycle, bridge) via {router}", end_record=True)


def test_crazyflies_emulate_stops_on_sigterm(router, tmp_path):
    pytest.importorskip("zenoh")
    _sigterm_ends_it(["crazyflies", "emulate", "--names", "cf1", "--router", router],
                     tmp_path / "cf.jsonl",
                     f"emulating Crazyflies cf1 (Crazyswarm2 over rmw_zenoh) via {router}",
                     end_record=False)
