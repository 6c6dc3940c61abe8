"""A stop lands soon in a long run: the progress callback, where a stop is
raised (the editor's Cancel, Ctrl-C's handler), is called by wall time as
well as by fraction of the run.

* NumPy engine: about 100 times a run and at least every
  ``run_loop.REPORT_SECONDS``; with that set to 0 it is called after every
  step (counted), with it infinite only by fraction (counted).
* Compiled engine: the first segment measures the pace and the others are
  sized to take about ``segments.SEGMENT_SECONDS``; with that set tiny the
  run goes one sample per segment and still gives the one-scan run's
  values bit for bit, and a stop lands after the first sample it can.

No wall-clock time is asserted: the policies are driven by setting their
time constants, and checked by counting calls and comparing values."""

import os

import numpy as np
import pytest

import avblocks as av
from avblocks.core import run_loop
from avblocks.core.compiled import segments


def fleet(n=4, seed=0):
    rng = np.random.default_rng(seed)
    p0 = np.column_stack([rng.uniform(-2, 2, (n, 2)), rng.uniform(-3, 3, n)])
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
    law = d.add(av.controllers.PointToPoint(rng.uniform(-2, 2, (n, 1, 2)), gain=0.8),
                name="law")
    d.connect(f.pose, law.pose)
    d.connect(law.cmd, f.cmd)
    return d


def test_numpy_engine_reports_by_wall_time(monkeypatch):
    calls = []
    monkeypatch.setattr(run_loop, "REPORT_SECONDS", 0.0)
    av.simulate(fleet(), 3.0, dt=0.01, progress=lambda k, n: calls.append(k))
    assert calls == list(range(1, 301))          # every step: 0 s between reports
    calls.clear()
    monkeypatch.setattr(run_loop, "REPORT_SECONDS", float("inf"))
    av.simulate(fleet(), 3.0, dt=0.01, progress=lambda k, n: calls.append(k))
    assert calls == [3 * (j + 1) for j in range(100)]    # by fraction only


def test_numpy_engine_stop_by_time_keeps_the_prefix(monkeypatch):
    monkeypatch.setattr(run_loop, "REPORT_SECONDS", 0.0)
    full = av.simulate(fleet(seed=1), 3.0, dt=0.01, progress=False)

    def stop(k, n):
        if k == 7:                               # not a multiple of the 1 % tick (3)
            raise KeyboardInterrupt
    res = av.simulate(fleet(seed=1), 3.0, dt=0.01, progress=stop)
    assert res.meta["interrupted"] and res.meta["interrupted_at"] == pytest.approx(0.07)
    assert len(res.t) == 8
    np.testing.assert_array_equal(res["fleet.pose"], full["fleet.pose"][:8])


def test_paced_length_policy():
    assert segments.paced_length(200, 0.01, 100) == 200     # 200 samples: 0.02 s
    # 1 ms a sample: 0.1 s is 100 samples, the power of two below is 64
    assert segments.paced_length(5000, 0.1, 100) == 64
    assert segments.paced_length(5000, 100.0, 1) == 1        # one sample at least
    assert segments.paced_length(50, 0.0, 10) == 50


@pytest.fixture
def need_jax():
    if os.environ.get("CI"):
        import jax  # noqa: F401  (in CI the jax extra is installed: never skip)
    else:
        pytest.importorskip("jax")


def test_compiled_segments_sized_by_pace_are_the_one_scan_run(monkeypatch, need_jax):
    kw = dict(t_final=20.0, dt=0.05, log=["fleet.pose"], log_every=2)   # 400 steps
    runner = av.compile(fleet(seed=3), **kw)
    whole = runner()
    monkeypatch.setattr(segments, "FIRST_STEPS", 16)
    monkeypatch.setattr(segments, "SEGMENT_SECONDS", 1e-12)
    calls = []
    seg = runner(progress=lambda k, n: calls.append(k))
    # the first segment: 8 samples (16 steps); then one sample (2 steps) each
    assert calls[:3] == [16, 18, 20] and calls[-1] == 400
    assert seg.meta["segments"] == 1 + (201 - 8)
    for k in whole.keys():
        assert np.array_equal(whole[k], seg[k]), k
    for k in whole.final_state:
        assert np.array_equal(whole.final_state[k], seg.final_state[k]), k

    def stop(k, n):
        if k >= 30:
            raise KeyboardInterrupt
    res = runner(progress=stop)
    assert res.meta["interrupted_at"] == pytest.approx(30 * 0.05)    # the first chance
    # 15 samples of 2 steps
    np.testing.assert_array_equal(res["fleet.pose"], whole["fleet.pose"][:15])
