"""Helpers of the Crazyflie tests: the emulator (``avblocks crazyflies
emulate``) as a subprocess on the test's Zenoh router, and its log."""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
import time
from pathlib import Path

from .conftest import env

#: Touch-down speed of a soft landing [m/s]: the landing trajectory ends
#: 0.03 m up (Crazyswarm2's examples' land height), where the motors stop and
#: the vehicle drops the rest: sqrt(2 g 0.03) = 0.77 m/s, plus what it still
#: carries from the trajectory's end (a fall from flight height: > 2 m/s).
SOFT_TOUCHDOWN = (2 * 9.81 * 0.03) ** 0.5 + 0.2


@contextlib.contextmanager
def cf_emulator(router, names, tmp_path, *extra):
    """Run the Crazyflie emulator as a subprocess; yields its log path."""
    log = Path(tmp_path) / f"cf-emulator-{time.monotonic_ns()}.jsonl"
    cmd = [sys.executable, "-m", "avblocks", "crazyflies", "emulate", "--names", names,
           "--router", router, "--log", str(log), *map(str, extra)]
    p = subprocess.Popen(cmd, env=env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True)
    try:
        t_end = time.monotonic() + 30
        while not (log.exists() and log.stat().st_size) and time.monotonic() < t_end:
            if p.poll() is not None:
                raise RuntimeError(f"emulator exited: {p.stdout.read()}")
            time.sleep(0.05)
        time.sleep(0.5)     # its queryables and subscriptions reach the router
        yield log
    finally:
        p.terminate()
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:  # pragma: no cover
            p.kill()


def read_log(path):
    with open(path) as f:
        return [json.loads(s) for s in f if s.strip()]


def events(recs, ev, vehicle=None):
    return [r for r in recs if r["ev"] == ev and (vehicle is None or r.get("vehicle") == vehicle)]


def wait_for(path, pred, timeout=20.0):
    """Poll the log at ``path`` until ``pred(records)`` is true; the records."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        recs = read_log(path) if Path(path).exists() else []
        if pred(recs):
            return recs
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting on {path}")
