"""The drone case study (``drone_formation``: five quadrotors forming a
turning 3-D crown) flown with ``avblocks run ... --robots crazyflies`` on
the Crazyflie emulator (subprocesses, real Zenoh router on loopback):
the same scenario file and the same outcome checks as in simulation, the
whole flight from takeoff to landing on the vehicles' side."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import avblocks as av

from ._cf import SOFT_TOUCHDOWN, cf_emulator, events, read_log
from .conftest import env

T_FINAL = 14.0          # the crown forms by 6 s, then flies 8 s of its circle
#: The checks of the simulation and of the MAVLink flight (test_mavlink_formation.py).
RMS_MAX, ERR_MAX, SEP_MIN = 0.2, 0.6, 0.6


def _check(numbers):
    """The checks a researcher makes in simulation and in flight alike."""
    assert numbers["formation_rms_m"] < RMS_MAX, numbers
    assert numbers["formation_max_m"] < ERR_MAX, numbers
    assert numbers["min_separation_m"] > SEP_MIN, numbers


def test_drone_formation_on_emulated_crazyflies_passes_the_simulations_checks(
        router, tmp_path):
    from avblocks.scenarios.drone_formation import outcome, start_positions
    # in simulation first
    res_sim = _simulate()
    _, num_sim = outcome(res_sim)
    _check(num_sim)
    # then on five emulated Crazyflies, started on the floor under the start line
    p0 = start_positions(5, 0.0).tolist()
    out = tmp_path / "out"
    with cf_emulator(router, "cf1,cf2,cf3,cf4,cf5", tmp_path, "--position0",
                     json.dumps(p0)) as log:
        p = subprocess.run([sys.executable, "-m", "avblocks", "run", "drone_formation",
                            "--robots", "crazyflies", "--cf-router", router, "--set",
                            f"t_final={T_FINAL:g}", "--out", str(out)], env=env(),
                            capture_output=True, text=True, timeout=240)
        assert p.returncode == 0, p.stdout + p.stderr
    recs = read_log(log)                # the emulator has ended: its log is complete
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "complete"
    _check(summary["numbers"])
    assert summary["numbers"]["min_separation_m"] == pytest.approx(
        num_sim["min_separation_m"], abs=0.1)
    assert (out / "paths.png").stat().st_size > 10_000
    # the vehicles' side: took off to the scenario's height (1.5 m), flew on
    # streamed set-points, landed on their trajectories, no watchdog
    for nm in ("cf1", "cf2", "cf3", "cf4", "cf5"):
        (tk,) = [e for e in events(recs, "service", nm) if e["service"] == "takeoff"]
        assert tk["request"]["height"] == pytest.approx(1.5)
        assert len([s for s in events(recs, "setpoint", nm) if s["accepted"]]) >= 200
        assert not [s for s in events(recs, "setpoint", nm) if not s["accepted"]]
        (g,) = events(recs, "ground", nm)
        assert g["mode"] in ("hl", "drop") and g["speed"] < SOFT_TOUCHDOWN
        assert events(recs, "wdt_level_out", nm) == []
    flight = [json.loads(s) for s in (out / "flight-log.jsonl").read_text().splitlines()]
    phases = [r["phase"] for r in flight if r["ev"] == "phase"]
    assert phases == ["preflight", "takeoff", "mission", "land", "landed"]
    assert recs[-1]["ev"] == "end" and recs[-1]["modes"] == ["landed"] * 5
    assert np.abs(np.array(recs[-1]["position"])[:, 2]).max() == 0.0


def _simulate():
    from avblocks.scenarios.drone_formation import make_diagram
    d, sim = make_diagram(t_final=T_FINAL)
    return av.simulate(d, **sim, progress=False)
