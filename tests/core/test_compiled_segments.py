"""A compiled run given ``progress`` runs in segments
(:mod:`avblocks.core.compiled.segments`): it reports rising progress up to
the whole run, gives the one-scan run's values bit for bit, compiles one
segment program for every run, and a ``KeyboardInterrupt`` raised from the
callback stops it with the samples so far, as the NumPy engine does. The
stopped run's state is checked against the NumPy engine run to that time."""

import os

import numpy as np
import pytest

import avblocks as av
from avblocks.core.compiled import cache_info, segments
from avblocks.core.errors import ParameterError
from avblocks.scenarios.flocking import make_diagram

if os.environ.get("CI"):
    import jax  # noqa: F401  (in CI the jax extra is installed: never skip)
else:
    pytest.importorskip("jax")
pytestmark = pytest.mark.jax


def fleet(n=4, seed=0):
    """Unicycles driven by the point-to-point law (integer and boolean
    discrete states) through a zero-order hold of three steps (a periodic
    block: held outputs in the carry)."""
    rng = np.random.default_rng(seed)
    p0 = np.column_stack([rng.uniform(-2, 2, (n, 2)), rng.uniform(-3, 3, n)])
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
    law = d.add(av.controllers.PointToPoint(rng.uniform(-2, 2, (n, 1, 2)), gain=0.8),
                name="law")
    hold = d.add(av.blocks.ZeroOrderHold(0.15), name="hold")
    d.connect(f.pose, law.pose)
    d.connect(law.cmd, hold.u)
    d.connect(hold.y, f.cmd)
    return d


# 401 steps logged every 3rd: 134 samples and 2 steps left after the last
KW = dict(t_final=20.05, dt=0.05, log=["fleet.pose", "hold.y"], log_every=3)


def test_progress_rises_to_the_whole_run_in_segments():
    d = fleet()
    calls = []
    res = av.simulate(d, backend="jax", progress=lambda k, n: calls.append((k, n)), **KW)
    steps = 401
    length = segments.segment_length(134, 3)
    assert length == 17                         # 50 steps at least: 17 samples of 3
    assert [n for _, n in calls] == [steps] * len(calls)
    done = [k for k, _ in calls]
    assert done == [min(3 * length * (j + 1), 399) for j in range(len(calls) - 1)] + [steps]
    assert len(calls) == res.meta["segments"] == -(-134 // length) == 8
    assert all(b > a for a, b in zip(done, done[1:]))
    assert "interrupted" not in res.meta


def test_segments_give_the_one_scan_run_bit_for_bit_without_more_compiles():
    d = fleet(seed=1)
    runner = av.compile(d, **{k: v for k, v in KW.items()})
    whole = runner()
    seg = runner(progress=lambda k, n: None)
    for k in whole.keys():
        assert np.array_equal(whole[k], seg[k]), k
    for k in whole.final_state:
        assert np.array_equal(whole.final_state[k], seg.final_state[k]), k
    np.testing.assert_array_equal(whole.t, seg.t)
    # the NumPy engine agrees (independent engine)
    ref = av.simulate(fleet(seed=1), progress=False, **KW)
    np.testing.assert_allclose(seg["fleet.pose"], ref["fleet.pose"], atol=1e-9)
    # one segment program for every later run: other values, seeds, x0
    before = cache_info()
    traces = runner.compilations
    for kw in ({}, {"params": {"law.gain": 0.3}, "seed": 4},
               {"x0": {"fleet.pose": np.zeros((4, 3))}}):
        a = runner(progress=lambda k, n: None, **kw)
        b = runner(**kw)
        np.testing.assert_array_equal(a["fleet.pose"], b["fleet.pose"])
    after = cache_info()
    assert runner.compilations == traces
    assert after["traces"] == before["traces"]
    assert after["xla_compiled"] == before["xla_compiled"]


def test_a_neighbour_search_run_in_segments_is_the_one_scan_run():
    d, _settings = make_diagram(agents=12, spread=20.0)
    kw = dict(t_final=4.0, dt=0.02, log_every=5, log=["flock.position", "view.order"])
    whole = av.simulate(d, backend="jax", **kw)
    calls = []
    seg = av.simulate(d, backend="jax", progress=lambda k, n: calls.append(k), **kw)
    # 41 samples in segments of 10 (50 steps): the 5th only logs the last
    # sample, and reports nothing new
    assert calls == [50, 100, 150, 200] and seg.meta["segments"] == 5
    for k in whole.keys():
        assert np.array_equal(whole[k], seg[k]), k


def test_a_stop_from_the_callback_keeps_the_prefix_and_the_state_reached():
    d = fleet(seed=2)
    full = av.simulate(d, backend="jax", **KW)

    def stop(k, n):
        if k >= n // 2:
            raise KeyboardInterrupt
    res = av.simulate(d, backend="jax", progress=stop, **KW)
    assert res.meta["interrupted"] is True
    assert res.meta["interrupted_by"] == "SIGINT"
    # segments of 17 samples (51 steps): stopped after the 4th, at step 204
    assert res.meta["interrupted_at"] == pytest.approx(204 * 0.05)
    count = 4 * 17
    assert len(res.t) == count
    np.testing.assert_array_equal(res.t, full.t[:count])
    for k in full.keys():
        np.testing.assert_array_equal(res[k], full[k][:count])
    # the state reached: the NumPy engine run to the same time
    ref = av.simulate(fleet(seed=2), t_final=204 * 0.05, dt=0.05, progress=False,
                      log=["fleet.pose"])
    np.testing.assert_allclose(res.final_state["fleet.pose"],
                               ref.final_state["fleet.pose"], atol=1e-9)
    # the NumPy engine marks its stopped runs with the same keys
    np_res = av.simulate(fleet(seed=2), progress=stop, **KW)
    assert {"interrupted", "interrupted_at", "interrupted_by"} <= set(np_res.meta)
    assert {"interrupted", "interrupted_at", "interrupted_by"} <= set(res.meta)


def test_a_cancel_subclass_names_itself():
    class Cancelled(KeyboardInterrupt):
        signal_name = "cancelled"

    def stop(k, n):
        raise Cancelled
    res = av.simulate(fleet(), backend="jax", progress=stop, **KW)
    assert res.meta["interrupted_by"] == "cancelled"
    assert len(res.t) == 17 and res.meta["interrupted_at"] == pytest.approx(51 * 0.05)


def test_a_wrong_progress_is_refused_by_name():
    with pytest.raises(ParameterError, match="progress"):
        av.simulate(fleet(), backend="jax", progress="yes", **KW)


def test_segment_length_policy():
    assert segments.segment_length(1001, 1) == 50          # 50 segments of 50 steps
    assert segments.segment_length(10001, 1) == 201        # at most 50 segments
    assert segments.segment_length(201, 5) == 10           # 50 steps at least
    assert segments.segment_length(3, 100) == 1            # one sample at least
    assert segments.segment_length(2, 1) == 2              # never more than the run


def test_progress_true_shows_a_bar_over_the_segments(capsys):
    d = fleet(seed=3)
    whole = av.simulate(d, backend="jax", **KW)
    res = av.simulate(d, backend="jax", progress=True, **KW)
    assert res.meta["segments"] == 8
    np.testing.assert_array_equal(res["fleet.pose"], whole["fleet.pose"])
    err = capsys.readouterr().err
    assert "0/401" in err and "step/s" in err     # tqdm's bar over the 401 steps
