"""Fixtures for robot-interface tests: a Zenoh router opened in-process on a
free loopback port and robot emulators started as subprocesses. Real
middleware, no mocks. Without eclipse-zenoh/rosbags the tests skip on a
user's machine, and fail in CI (CI is set)."""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

SRC = str(Path(__file__).resolve().parents[2] / "src")


def _need(mod):
    try:
        __import__(mod)
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip(f"{mod} not installed (extra [ros2])")


@pytest.fixture(scope="module")
def router():
    _need("zenoh")
    _need("rosbags")
    from avblocks.interfaces.ros2 import open_router
    session, endpoint = open_router()
    yield endpoint
    session.close()


def env():
    e = dict(os.environ)
    e["PYTHONPATH"] = SRC + os.pathsep + e.get("PYTHONPATH", "")
    return e


@contextlib.contextmanager
def emulator(router, names, tmp_path, *extra, wait=True):
    """Run ``avblocks robots emulate`` as a subprocess; yields the log path."""
    log = Path(tmp_path) / f"emulator-{time.monotonic_ns()}.jsonl"
    cmd = [sys.executable, "-m", "avblocks", "robots", "emulate", "--names", names,
           "--router", router, "--log", str(log), *map(str, extra)]
    p = subprocess.Popen(cmd, env=env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True)
    try:
        if wait:
            t_end = time.monotonic() + 20
            while not (log.exists() and log.stat().st_size) and time.monotonic() < t_end:
                if p.poll() is not None:
                    raise RuntimeError(f"emulator exited: {p.stdout.read()}")
                time.sleep(0.05)
            time.sleep(0.3)     # its subscriptions reach the router
        yield log
    finally:
        p.terminate()
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:  # pragma: no cover
            p.kill()


def wait_for_stop(log, robots, timeout=3.0):
    """Wait (bounded) until each robot's last received command is zero: the
    stop commands of on_stop may still be in flight through the router when
    the run returns."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        recs = read_log(log) if Path(log).exists() else []
        last = [commands(recs, r)[-1] if commands(recs, r) else None for r in robots]
        if all(c is not None and c["v"] == 0.0 and c["w"] == 0.0 for c in last):
            return
        time.sleep(0.05)


def read_log(path):
    with open(path) as f:
        return [json.loads(s) for s in f if s.strip()]


def commands(recs, robot=None):
    return [r for r in recs if r["ev"] == "cmd" and (robot is None or r["robot"] == robot)]
