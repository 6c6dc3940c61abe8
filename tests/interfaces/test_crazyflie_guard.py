"""The guard (``avblocks crazyflies guard``) watches the commander's
set-points, not its socket: whatever stops them (a SIGKILLed commander, a
frozen one under SIGSTOP, a network link cut between the commander and the
router) it lands the vehicles within its stated time after the last
set-point, and it leaves alone a commander whose diagram is merely slow
(the sender keeps streaming) or that lands its vehicles itself.

Real processes over a real Zenoh router on loopback: the emulator, the
guard (its command-line tool) and the commander (``_cf_fleet_run.py``) are
three subprocesses. The times are read from the emulator's log, on its own
clock: when the firmware took the commander's last set-point (``at``)
against when the guard's ``land`` request came in. The network cut: the
commander reaches the router through a TCP relay in this process that stops
forwarding both ways and keeps every socket open, as a dropped Wi-Fi link
does (no FIN, no RST: the router would notice only at the Zenoh lease,
10 s)."""

from __future__ import annotations

import contextlib
import json
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from ._cf import SOFT_TOUCHDOWN, cf_emulator, events, wait_for
from .conftest import env

HERE = Path(__file__).resolve().parent
NAMES = ("cf1", "cf2")
P0 = "[[0, 0, 0], [0, 1, 0]]"
#: The guard's stated time without set-points before it lands [s] (its default).
TIMEOUT = 0.4
#: Room above TIMEOUT for its check period (10 ms), the notify round trip
#: and a loaded 2-core machine; far under the firmware's 2 s motor cut.
MARGIN = 0.3


class Relay:
    """A TCP relay on 127.0.0.1 to ``target`` (host, port); :meth:`cut`
    stops forwarding both ways and keeps every socket open."""

    def __init__(self, target):
        self.target = target
        self.srv = socket.socket()
        self.srv.bind(("127.0.0.1", 0))
        self.srv.listen()
        self.port = self.srv.getsockname()[1]
        self._cut = threading.Event()
        self._closed = threading.Event()
        self._socks = [self.srv]
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        while not self._closed.is_set():
            try:
                a, _ = self.srv.accept()
            except OSError:
                return
            b = socket.create_connection(self.target)
            self._socks += [a, b]
            for src, dst in ((a, b), (b, a)):
                threading.Thread(target=self._pump, args=(src, dst), daemon=True).start()

    def _pump(self, src, dst):
        while not self._closed.is_set():
            if self._cut.is_set():              # hold everything: read no more
                self._closed.wait(0.05)
                continue
            try:
                data = src.recv(65536)
                if not data:
                    return
                if self._cut.is_set():          # read just before the cut: drop it
                    continue
                dst.sendall(data)
            except OSError:
                return

    def cut(self):
        self._cut.set()

    def close(self):
        self._closed.set()
        for s in self._socks:
            with contextlib.suppress(OSError):
                s.close()


@contextlib.contextmanager
def _guard(router, tmp_path):
    glog = tmp_path / "guard.jsonl"
    g = subprocess.Popen([sys.executable, "-m", "avblocks", "crazyflies", "guard",
                          "--names", ",".join(NAMES), "--router", router, "--log", str(glog),
                          "--land-duration", "1.5"], env=env(),
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        line = g.stdout.readline()
        assert "guarding Crazyflies cf1,cf2" in line and f"{TIMEOUT:g} s" in line, line
        yield glog
    finally:
        g.terminate()
        g.wait(10)


def _commander(router, tmp_path, *opts, t_final=60):
    flight, results = tmp_path / "flight.jsonl", tmp_path / "results.nc"
    p = subprocess.Popen([sys.executable, str(HERE / "_cf_fleet_run.py"), router,
                          ",".join(NAMES), str(t_final), str(flight), str(results), *opts],
                         env=env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True)
    t_end = time.monotonic() + 40
    while time.monotonic() < t_end:
        line = p.stdout.readline()
        if "started" in line:
            return p
        if not line and p.poll() is not None:
            break
    p.kill()
    raise AssertionError(f"commander did not start: {p.stdout.read()}")


def _end(p):
    if p.poll() is None:
        p.send_signal(signal.SIGKILL)
        p.send_signal(signal.SIGCONT)
    p.wait(10)


def _guard_landed(log, glog, after, cause):
    """Every vehicle: the guard's notify_setpoints_stop then land, the land
    ``TIMEOUT`` (+ MARGIN at most) after the commander's last set-point, a
    soft touch-down, no motor cut. Returns {vehicle: seconds}."""
    recs = wait_for(log, lambda r: all(
        [e for e in events(r, "ground", nm) if e["wall"] > after] for nm in NAMES),
        timeout=20)
    times = {}
    for nm in NAMES:
        last = [s for s in events(recs, "setpoint", nm) if s["accepted"]][-1]
        srv = [e for e in events(recs, "service", nm) if e["wall"] > after]
        assert [e["service"] for e in srv][:2] == ["notify_setpoints_stop", "land"], srv
        land = srv[1]
        assert land["request"]["duration"] == 1.5
        times[nm] = land["at"] - last["at"]
        if cause != "sigkill":      # the commander's session lives on: only the
            assert times[nm] > TIMEOUT - 0.02, (cause, nm, times[nm])   # set-points tell
        assert times[nm] < TIMEOUT + MARGIN, (cause, nm, times[nm])
        assert events(recs, "wdt_motors_off", nm) == []
        assert events(recs, "landing_cancelled", nm) == []
        (g,) = [e for e in events(recs, "ground", nm) if e["wall"] > after]
        assert g["mode"] in ("hl", "drop") and g["speed"] < SOFT_TOUCHDOWN, g
    gl = [json.loads(s) for s in Path(glog).read_text().splitlines()]
    done = [r for r in gl if r["ev"] == "landed_by_guard"]
    assert sorted(r["vehicle"] for r in done) == list(NAMES) and all(r["ok"] for r in done)
    print(f"guard, {cause}: last set-point -> land "
          + ", ".join(f"{nm} {1000 * t:.0f} ms" for nm, t in times.items())
          + " (" + ", ".join(sorted({r["reason"] for r in done})) + ")")
    return times, done


@pytest.mark.parametrize("cause", ["sigkill", "sigstop"])
def test_the_guard_lands_a_killed_or_frozen_commanders_vehicles_in_its_time(
        router, tmp_path, cause):
    with cf_emulator(router, ",".join(NAMES), tmp_path, "--position0", P0) as log, \
            _guard(router, tmp_path) as glog:
        p = _commander(router, tmp_path)
        try:
            time.sleep(1.0)
            t0 = time.time()
            p.send_signal(signal.SIGKILL if cause == "sigkill" else signal.SIGSTOP)
            times, done = _guard_landed(log, glog, t0, cause)
        finally:
            _end(p)
    if cause == "sigstop":      # the process lives (its socket, its claim): the
        assert {r["reason"] for r in done} == {       # stream's end tells
            f"no set-point for more than {TIMEOUT:g} s"}


def test_the_guard_lands_the_vehicles_of_a_commander_whose_network_link_is_cut(
        router, tmp_path):
    host, port = router.split("/", 1)[1].rsplit(":", 1)
    relay = Relay((host, int(port)))
    try:
        with cf_emulator(router, ",".join(NAMES), tmp_path, "--position0", P0) as log, \
                _guard(router, tmp_path) as glog:
            p = _commander(f"tcp/127.0.0.1:{relay.port}", tmp_path)
            try:
                time.sleep(1.0)
                t0 = time.time()
                relay.cut()
                times, done = _guard_landed(log, glog, t0, "network cut")
            finally:
                _end(p)
    finally:
        relay.close()
    assert {r["reason"] for r in done} == {f"no set-point for more than {TIMEOUT:g} s"}


def test_a_slow_diagram_step_keeps_the_stream_and_a_normal_end_is_left_to_the_commander(
        router, tmp_path):
    """A step that takes 0.8 s (over the guard's 0.4 s and the firmware's 0.5 s
    level-out, under the block's 1 s stall watchdog): the sender streams the held
    set-point on; the guard does nothing, then or at the commander's own landing."""
    with cf_emulator(router, ",".join(NAMES), tmp_path, "--position0", P0) as log, \
            _guard(router, tmp_path) as glog:
        p = _commander(router, tmp_path, "--pause-at", "1.0", "--pause", "0.8", t_final=3)
        try:
            out, _ = p.communicate(timeout=60)
        finally:
            _end(p)
        assert "pausing 0.8 s" in out and "saved" in out, out
        recs = wait_for(log, lambda r: all(events(r, "ground", nm) for nm in NAMES),
                        timeout=20)
    flight = [json.loads(s) for s in (tmp_path / "flight.jsonl").read_text().splitlines()]
    cmds = [r["wall"] for r in flight if r["ev"] == "cmd"]
    assert max(b - a for a, b in zip(cmds, cmds[1:])) > 0.75     # the pause happened
    for nm in NAMES:
        at = [s["at"] for s in events(recs, "setpoint", nm) if s["accepted"]]
        # the stream at 50 Hz went on through the pause (a loaded machine: 0.15 s)
        assert len(at) > 100 and max(b - a for a, b in zip(at, at[1:])) < 0.15
        assert events(recs, "wdt_level_out", nm) == []
        srv = [e["service"] for e in events(recs, "service", nm)]
        assert srv == ["takeoff", "notify_setpoints_stop", "land"], srv
    gl = [json.loads(s) for s in glog.read_text().splitlines()]
    assert [r for r in gl if r["ev"] == "landed_by_guard"] == []
    assert sorted(r["vehicle"] for r in gl if r["ev"] == "commander_lands") == list(NAMES)


def test_a_commander_killed_as_its_takeoff_begins_is_landed_once_its_vehicles_rise(
        router, tmp_path):
    """Killed right after its takeoff requests, the vehicles still on the
    floor (the guard's claim watch saw them "not flying"): the firmware flies
    the takeoff on, and they would hover until their batteries die. The guard
    lands them as they leave the floor."""
    flight, results = tmp_path / "flight.jsonl", tmp_path / "results.nc"
    with cf_emulator(router, ",".join(NAMES), tmp_path, "--position0", P0) as log, \
            _guard(router, tmp_path) as glog:
        p = subprocess.Popen([sys.executable, str(HERE / "_cf_fleet_run.py"), router,
                              ",".join(NAMES), "30", str(flight), str(results)], env=env(),
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            wait_for(log, lambda r: all(
                [e for e in events(r, "service", nm) if e["service"] == "takeoff"]
                for nm in NAMES), timeout=40)
            p.send_signal(signal.SIGKILL)
            t0 = time.time()
            recs = wait_for(log, lambda r: all(
                [e for e in events(r, "ground", nm) if e["wall"] > t0] for nm in NAMES),
                timeout=20)
        finally:
            _end(p)
    gl = [json.loads(s) for s in Path(glog).read_text().splitlines()]
    gone = [r for r in gl if r["ev"] == "commander_gone"]
    assert gone and not any(r["flying"] for r in gone)      # on the floor when it died
    done = [r for r in gl if r["ev"] == "landed_by_guard"]
    assert sorted(r["vehicle"] for r in done) == list(NAMES) and all(r["ok"] for r in done)
    assert {r["reason"] for r in done} == {"commander gone during its takeoff"}
    for nm in NAMES:
        srv = [e["service"] for e in events(recs, "service", nm)]
        assert srv == ["takeoff", "notify_setpoints_stop", "land"], srv
        # it had left the floor (5 cm) and no higher than 0.3 m of its 0.5 m
        (plan,) = [e for e in events(recs, "plan", nm) if e["kind"] == "land"]
        assert 0.05 < plan["from"][2] < 0.3, plan
        (g,) = [e for e in events(recs, "ground", nm) if e["wall"] > t0]
        assert g["speed"] < SOFT_TOUCHDOWN, g
