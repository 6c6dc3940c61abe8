"""The flight layer's pre-flight and fail-safe reporting, on both emulated
fleets (subprocesses, real middleware on loopback):

* the vehicles are matched to the scenario's start slots by where they
  stand (shuffled names fly the agents whose slots they stand on; truth: a
  brute-force search over every permutation, and the set-points each
  emulator received); a vehicle too far from any slot, or left with a far
  slot, is refused by name before anything is sent;
* the documented ``--geofence -4,4,-3,5,0,3`` parses (argparse took the
  leading minus for an option);
* vehicles that go silent together (a MAVLink emulator or a router that
  dies): the fail-safe names every one, not only the one whose last pose
  happened to be oldest; no landing can be confirmed, and the log says so.
"""

from __future__ import annotations

import itertools
import json
import time
from pathlib import Path

import numpy as np
import pytest

import avblocks as av

from ._cf import cf_emulator, events, read_log

#: Three start slots on a line along x, 1 m apart, at the scenario's height.
SLOTS = np.array([[-1.0, 0.0, 1.5], [0.0, 0.0, 1.5], [1.0, 0.0, 1.5]])
#: Agent k's velocity command: each vehicle's set-points say which agent it flies.
V = np.array([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, -0.1, 0.0]])


def _best(positions):
    """agent -> vehicle index minimising the summed (x, y) distance, by brute force."""
    p = np.asarray(positions, float)[:, :2]
    return min(itertools.permutations(range(len(p))),
               key=lambda perm: sum(np.linalg.norm(p[v] - SLOTS[k, :2])
                                    for k, v in enumerate(perm)))


def _diagram(fleet):
    d = av.Diagram()
    c = d.add(av.blocks.Constant(V), name="c")
    f = d.add(fleet, name="fleet")
    d.connect(c.y, f.velocity)
    return d


def test_the_documented_geofence_with_a_leading_minus_parses():
    from avblocks.cli import build_parser
    from avblocks.core.errors import ParameterError
    from avblocks.interfaces.flight.cli import flight_options
    for argv in (["--geofence", "-4,4,-3,5,0,3"], ["--geofence=-4,4,-3,5,0,3"]):
        args = build_parser().parse_args(["run", "drone_formation", "--robots", "crazyflies",
                                          *argv, "--min-separation", "0.4"])
        assert flight_options(args)["geofence"] == [-4.0, 4.0, -3.0, 5.0, 0.0, 3.0]
        assert args.min_separation == 0.4
    args = build_parser().parse_args(["run", "drone_formation", "--geofence", "-4,a"])
    with pytest.raises(ParameterError, match="six numbers"):
        flight_options(args)


def test_shuffled_crazyflies_fly_the_agents_whose_slots_they_stand_on(router, tmp_path):
    from avblocks.interfaces.crazyflie import Crazyflies
    # cf1 stands at the third slot, cf2 at the first, cf3 at the second (a few cm off)
    pos = [[1.05, 0.02, 0.0], [-0.97, 0.03, 0.0], [0.02, -0.04, 0.0]]
    flight = tmp_path / "flight.jsonl"
    with cf_emulator(router, "cf1,cf2,cf3", tmp_path, "--position0", json.dumps(pos)) as log:
        fleet = Crazyflies(["cf1", "cf2", "cf3"], router, takeoff_height=0.4,
                           land_duration=1.0, slots=SLOTS, log=str(flight))
        res = av.simulate(_diagram(fleet), t_final=0.5, dt=0.05, realtime=1.0,
                          log=["fleet.position"], progress=False)
        time.sleep(0.3)
    recs = read_log(log)
    order = _best(pos)
    assert order == (1, 2, 0)
    assert fleet.agent_names == ["cf2", "cf3", "cf1"]
    for k, i in enumerate(order):
        nm = f"cf{i + 1}"
        sps = [s for s in events(recs, "setpoint", nm) if s["accepted"]]
        assert len(sps) > 10 and all(s["vel"] == V[k].tolist() for s in sps), nm
        # agent k's output is that vehicle's pose
        assert res["fleet.position"][0, k, :2] == pytest.approx(pos[i][:2], abs=0.01)
    (m,) = [json.loads(s) for s in flight.read_text().splitlines()
            if json.loads(s)["ev"] == "slots"]
    assert [e["vehicle"] for e in m["mapping"]] == ["cf2", "cf3", "cf1"] and m["reordered"]
    assert [e["distance"] for e in m["mapping"]] == pytest.approx(
        [np.hypot(0.03, 0.03), np.hypot(0.02, 0.04), np.hypot(0.05, 0.02)], abs=1e-3)


def test_a_misplaced_crazyflie_is_refused_by_name_and_nothing_is_sent(router, tmp_path):
    from avblocks.interfaces.crazyflie import Crazyflies
    from avblocks.interfaces.flight import PreflightError
    # cf1 on the first slot, cf2 next to it (the second slot is left to it, 0.91 m
    # away), cf3 0.9 m beside the third
    pos = [[-1.0, 0.0, 0.0], [-0.9, 0.1, 0.0], [1.0, 0.9, 0.0]]
    with cf_emulator(router, "cf1,cf2,cf3", tmp_path, "--position0", json.dumps(pos)) as log:
        fleet = Crazyflies(["cf1", "cf2", "cf3"], router, slots=SLOTS, wait=3.0)
        with pytest.raises(PreflightError) as e:
            av.simulate(_diagram(fleet), t_final=0.5, dt=0.05, realtime=1.0,
                        progress=False)
        time.sleep(0.3)
    msg = str(e.value)
    assert ("cf2 at (-0.90, 0.10) is 0.91 m from the start slot left for it (agent 1, "
            "at (0.00, 0.00); another vehicle stands nearer its nearest one): more than "
            "slot_tolerance 0.5 m") in msg
    assert ("cf3 at (1.00, 0.90) is 0.90 m from the nearest start slot (agent 2, at "
            "(1.00, 0.00)): more than slot_tolerance 0.5 m") in msg
    assert "cf1" not in msg
    recs = read_log(log)
    assert events(recs, "service") == [] and events(recs, "setpoint") == []
    # with a tolerance that takes any placement, the same vehicles pass pre-flight
    assert Crazyflies(["cf1", "cf2", "cf3"], slots=SLOTS,
                      slot_tolerance=float("inf")).slot_tolerance == float("inf")


def test_shuffled_and_misplaced_mavlink_vehicles(tmp_path):
    from avblocks.interfaces.flight import PreflightError
    from avblocks.interfaces.mavlink import Drones

    from ._mavlink import emulator, received
    pos = [[0.03, 0.01, 0.0], [0.98, -0.02, 0.0], [-1.01, 0.0, 0.0]]
    with emulator(tmp_path, 3, pose0=pos) as (log, spec):
        drones = Drones(spec, n=3, takeoff_height=1.0, slots=SLOTS)
        av.simulate(_diagram(drones), t_final=0.5, dt=0.05, realtime=1.0, progress=False)
    order = _best(pos)
    assert order == (2, 0, 1) and drones.agent_names == ["uav3", "uav1", "uav2"]
    for k, i in enumerate(order):
        vel = [m for _, m in received(log, i + 1, "SET_POSITION_TARGET_LOCAL_NED")
               if m.type_mask == 1479 and (m.vx or m.vy or m.vz)]
        # ENU -> NED by hand: north = y, east = x, down = -z
        want = np.float32([V[k, 1], V[k, 0], -V[k, 2]])
        assert vel and all(np.array_equal(np.float32([m.vx, m.vy, m.vz]), want)
                           for m in vel), (k, i)
    pos[1] = [0.98, 0.7, 0.0]
    with emulator(tmp_path, 3, pose0=pos) as (log, spec):
        drones = Drones(spec, n=3, slots=SLOTS, wait=3.0)
        with pytest.raises(PreflightError, match=r"uav2 at \(0\.98, 0\.70\) is 0\.70 m from "
                                                 r"the nearest start slot \(agent 2"):
            av.simulate(_diagram(drones), t_final=0.5, dt=0.05, realtime=1.0,
                        progress=False)
    # nothing was commanded: heartbeats, telemetry requests (SET_MESSAGE_INTERVAL)
    # and parameter reads only, the MAVLink block's pre-flight traffic
    for sid in (1, 2, 3):
        types = {r["type"] for r, _ in received(log, sid)}
        assert types <= {"HEARTBEAT", "COMMAND_LONG", "PARAM_REQUEST_READ"}, types
        assert {m.command for _, m in received(log, sid, "COMMAND_LONG")} <= {511}


def test_vehicles_going_silent_together_are_all_named(tmp_path):
    """A MAVLink emulator (or a router) that dies takes every vehicle's link,
    each on its own UDP socket and receive thread, their last packets a few ms
    apart: the vehicle whose last pose is oldest crosses the timeout first and
    the fail-safe fired naming it alone. Here the five go silent 0.1 s apart
    (deterministic; a killed emulator does the same with a smaller spread):
    every one of them is named."""
    from avblocks.interfaces.flight import FailsafeError
    from avblocks.interfaces.mavlink import Drones

    from ._mavlink import emulator
    n = 5
    silent = [f"--silent={k + 1}@{1.0 + 0.1 * k:.1f}" for k in range(n)]
    with emulator(tmp_path, n, *silent) as (log, spec):
        drones = Drones(spec, n=n, takeoff_height=1.0,
                        log=str(tmp_path / "flight.jsonl"))
        d = av.Diagram()
        c = d.add(av.blocks.Constant(np.zeros((n, 3))), name="c")
        f = d.add(drones, name="fleet")
        d.connect(c.y, f.velocity)
        with pytest.raises(FailsafeError) as e:
            av.simulate(d, t_final=30, dt=0.05, realtime=1.0, progress=False)
    names = [f"uav{k + 1}" for k in range(n)]
    assert e.value.reason == "silent"
    assert sorted(e.value.vehicles) == names, str(e.value)
    msg = str(e.value)
    assert "nothing heard from ['uav1']" in msg and all(nm in msg for nm in names), msg
    fl = [json.loads(s) for s in Path(tmp_path / "flight.jsonl").read_text().splitlines()]
    (fs,) = [r for r in fl if r["ev"] == "failsafe"]
    assert sorted(fs["vehicles"]) == names
    # nobody can confirm a landing: each is logged as unconfirmed, none as landed
    (unc,) = [r for r in fl if r["ev"] == "land_unconfirmed"]
    assert sorted(unc["vehicles"]) == names
    assert [r for r in fl if r["ev"] == "landed"] == []
