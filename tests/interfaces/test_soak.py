"""The 2-minute version of ``benchmarks/soak.py``: 20 emulated robots over
Zenoh at 50 Hz for one minute, and 2e5 steps of the NumPy engine with a
decimated log, in a fresh process (so that its resident memory is the
run's own). Marked ``soak`` (and ``slow``): select with ``-m soak``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from .conftest import _need, env

SOAK = Path(__file__).resolve().parents[2] / "benchmarks" / "soak.py"


@pytest.mark.soak
@pytest.mark.slow
def test_two_minute_soak_memory_flat_no_miss_growth_results_complete(tmp_path):
    _need("zenoh")
    _need("rosbags")
    out = tmp_path / "soak.json"
    p = subprocess.run([sys.executable, str(SOAK), "--minutes", "1", "--steps", "200000",
                        "--json", str(out), "--plot", str(tmp_path / "soak.png")],
                       env=env(), capture_output=True, text=True, timeout=600)
    assert p.returncode in (0, 1), p.stdout + p.stderr
    robots, numpy_run = json.loads(out.read_text())
    print(p.stdout)
    for part in (robots, numpy_run):
        assert part["results_complete"], part
        assert part["samples"] == part["samples_expected"]
        # resident memory flat within 5 % after warm-up
        assert part["rss_growth"] <= 0.05, part
        r = np.asarray(part["series"]["rss"], float)
        assert len(r) >= 20 and np.isfinite(r).all()
    # 50 Hz for 60 s; no growth of deadline misses from the first to the last third
    assert robots["steps"] == 3000
    assert robots["no_miss_growth"], robots
    assert robots["misses_total"] <= 0.05 * robots["steps"]
    assert robots["stale_samples"] == 0 and robots["watchdog_events"] == 0
    # the NumPy run: the circles' closed form after 2e5 RK4 steps
    assert numpy_run["final_pose_error_m"] < 1e-6
    assert (tmp_path / "soak.png").stat().st_size > 10_000
