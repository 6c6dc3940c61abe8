"""Helpers of the MAVLink tests: the emulator as a subprocess on free
loopback UDP ports, and an INDEPENDENT decoder of what it received (the
raw bytes it logged, parsed by pymavlink's own generated MAVLink 2 parser,
never by avblocks code)."""

from __future__ import annotations

import contextlib
import json
import os
import random
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from .conftest import env

CMD_LAND, CMD_ARM, CMD_SET_MODE = 21, 400, 176


def need_pymavlink():
    try:
        import pymavlink  # noqa: F401
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip("pymavlink not installed (extra [mavlink])")


def free_base_port(n, step=1, kind=socket.SOCK_DGRAM):
    """A port p such that p, p+step, ... (n of them) are free on 127.0.0.1
    (UDP, or TCP with ``kind=socket.SOCK_STREAM``)."""
    for _ in range(200):
        p = random.randint(20000, 60000 - n * step)
        socks = []
        try:
            for k in range(n):
                s = socket.socket(socket.AF_INET, kind)
                socks.append(s)
                s.bind(("127.0.0.1", p + k * step))
            return p
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError("no free ports")


@contextlib.contextmanager
def emulator(tmp_path, n, *extra, pose0=None, keep=None):
    """``avblocks mavlink emulate`` as a subprocess; yields (log, connections):
    the emulator's log and the commander's connection spec, reached as the
    real SITL is (PX4 / ``--link udp``: ``udpin:127.0.0.1:BASE+``;
    ArduPilot's TCP: ``tcp:127.0.0.1:BASE+10``). ``keep``, a dict, gets the
    process (``"process"``) and the vehicles' own UDP ports (``"vehicle_port"``,
    the first)."""
    need_pymavlink()
    extra = list(map(str, extra))
    tcp = ("--flavor" in extra and extra[extra.index("--flavor") + 1] == "ardupilot"
           and "--link" not in extra) or ("--link" in extra
                                         and extra[extra.index("--link") + 1] == "tcp")
    if tcp:
        base = free_base_port(n, 10, socket.SOCK_STREAM)
        ports = ["--base-port", str(base)]
        spec = f"tcp:127.0.0.1:{base}+10"
    else:
        base, vport = free_base_port(n), free_base_port(n)
        ports = ["--base-port", str(base), "--vehicle-port", str(vport)]
        spec = f"udpin:127.0.0.1:{base}+"
    log = Path(tmp_path) / f"mav-emulator-{time.monotonic_ns()}.jsonl"
    if pose0 is None:
        pose0 = [[2.0 * k, 0.0, 0.0] for k in range(n)]
    cmd = [sys.executable, "-m", "avblocks", "mavlink", "emulate", "--n", str(n),
           *ports, "--pose0", json.dumps(pose0), "--log", str(log), *extra]
    p = subprocess.Popen(cmd, env=env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True)
    if keep is not None:
        keep.update(process=p, vehicle_port=None if tcp else vport)
    try:
        t_end = time.monotonic() + 30
        while not (log.exists() and log.stat().st_size) and time.monotonic() < t_end:
            if p.poll() is not None:
                raise RuntimeError(f"emulator exited: {p.stdout.read()}")
            time.sleep(0.05)
        yield log, spec
    finally:
        p.terminate()
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:  # pragma: no cover
            p.kill()


def read_log(path):
    with open(path) as f:
        return [json.loads(s) for s in f if s.strip()]


def decode(rec):
    """The message of an emulator ``rx`` record, parsed from its raw bytes by
    pymavlink's generated MAVLink 2 parser (independent of avblocks)."""
    from pymavlink.dialects.v20 import common
    parser = common.MAVLink(None)
    msgs = parser.parse_buffer(bytes.fromhex(rec["hex"]))
    assert msgs and len(msgs) == 1, rec
    return msgs[0]


def received(log, sysid=None, mtype=None):
    """``[(record, decoded message)]`` the emulator received."""
    out = []
    for r in read_log(log):
        if r["ev"] != "rx" or (sysid is not None and r["sysid"] != sysid):
            continue
        if mtype is not None and r["type"] != mtype:
            continue
        out.append((r, decode(r)))
    return out


def sent_commands(log, sysid, command):
    """The COMMAND_LONGs with ``command`` the emulator received, decoded."""
    return [m for _, m in received(log, sysid, "COMMAND_LONG") if m.command == command]


def events(log, ev, sysid=None):
    return [r for r in read_log(log) if r["ev"] == ev
            and (sysid is None or r.get("sysid") == sysid)]


def wait_landed(log, n, timeout=15.0):
    """Wait until each of the n vehicles logged ``landed``; their records."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        got = {r["sysid"]: r for r in events(log, "landed")}
        if len(got) == n:
            return got
        time.sleep(0.1)
    return {r["sysid"]: r for r in events(log, "landed")}
