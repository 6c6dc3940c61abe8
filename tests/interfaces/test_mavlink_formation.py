"""The drone_formation case study: in simulation (the library's quadrotor
model) and, unchanged, on five emulated PX4 vehicles over MAVLink/UDP
(``avblocks run drone_formation --robots mavlink``), with the same outcome
checks (formation error, minimum separation)."""

import json
import subprocess
import sys

import numpy as np

from avblocks.scenarios import drone_formation as df

from ._mavlink import emulator, wait_landed
from .conftest import env

# the same thresholds for simulation and flight
RMS_MAX, ERR_MAX, SEP_MIN = 0.2, 0.6, 0.6


def test_planned_velocity_is_the_time_derivative_of_the_planned_position():
    p0 = df.start_positions(5, 1.5)
    ref = df.FormationReference(p0, df.crown_offsets(5), 1.5, 24.0, 6.0, 0.3)
    h = 1e-5
    for t in (0.5, 3.0, 5.99, 6.5, 12.0, 20.0):
        fd = (ref.output(t + h, {}, {}, np)["position"]
              - ref.output(t - h, {}, {}, np)["position"]) / (2 * h)
        np.testing.assert_allclose(ref.output(t, {}, {}, np)["velocity"], fd, atol=1e-6)
    # the plan starts at the start line and, after gather, the crown's slots
    # are radius 1 around a centre at the start height +- dz
    np.testing.assert_allclose(ref.output(0.0, {}, {}, np)["position"], p0)
    q = ref.output(6.0, {}, {}, np)["position"]
    c = q.mean(axis=0)
    np.testing.assert_allclose(np.linalg.norm(q[:, :2] - c[:2], axis=1), 1.0, atol=1e-12)
    assert sorted(np.round(q[:, 2] - 1.5, 12)) == [-0.3, -0.3, 0.3, 0.3, 0.3]


def _check(numbers):
    assert numbers["formation_rms_m"] < RMS_MAX, numbers
    assert numbers["formation_max_m"] < ERR_MAX, numbers
    assert numbers["min_separation_m"] > SEP_MIN, numbers


def _run(args, out):
    p = subprocess.run([sys.executable, "-m", "avblocks", "run", "drone_formation",
                        "--out", str(out), "--quiet", *args], env=env(),
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    return json.loads((out / "summary.json").read_text())


def test_case_study_in_simulation_and_on_the_mavlink_emulator(tmp_path):
    sim = _run([], tmp_path / "sim")
    _check(sim["numbers"])
    pose0 = df.start_positions(5, 0.0).tolist()          # on the ground
    with emulator(tmp_path, 5, pose0=pose0) as (log, spec):
        fly = _run(["--robots", "mavlink", "--mavlink-connect", spec], tmp_path / "fly")
        landed = wait_landed(log, 5)
    assert fly["status"] == "complete"
    _check(fly["numbers"])
    assert sorted(landed) == [1, 2, 3, 4, 5]
    assert (tmp_path / "fly" / "paths.png").stat().st_size > 10_000
    recs = [json.loads(s) for s in open(tmp_path / "fly" / "flight-log.jsonl")]
    phases = [r["phase"] for r in recs if r["ev"] == "phase"]
    assert phases == ["preflight", "takeoff", "mission", "land", "landed"]
