"""Scope block, plot_signals and plot_trajectories."""

import numpy as np
import pytest
from matplotlib.collections import LineCollection, PathCollection, PolyCollection
from shapely.geometry import Polygon

import avblocks as av
import avblocks.viz as viz


def unicycles(n, scope=None, T=2.0):
    rng = np.random.default_rng(0)
    pose0 = np.c_[rng.uniform(-5, 5, (n, 2)), rng.uniform(-3, 3, n)]
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=pose0), name="fleet")
    c = d.add(av.blocks.Constant(np.tile([1.0, 0.2], (n, 1))), name="c")
    d.connect(c.y, f.cmd)
    s = None
    if scope is not None:
        s = d.add(scope, name="scope")
        d.connect(f.pose, s.pose)
        d.connect(c.y, s.cmd)
    return av.simulate(d, T, dt=0.05, log=[f.pose]), s


def test_scope_records_what_is_logged(tmp_path):
    res, s = unicycles(3, viz.Scope(["pose", "cmd"], path=tmp_path / "scope.png"))
    rec = s.block.results
    assert np.allclose(rec.t, res.t)
    assert np.allclose(rec["pose"], res["fleet.pose"])
    assert rec["cmd"].shape == (len(res.t), 3, 2)
    assert rec.ports["pose"].labels == ("x", "y", "theta")
    assert (tmp_path / "scope.png").stat().st_size > 1000
    fig = s.block.plot()
    assert len(fig.axes) == 5
    assert [ax.get_ylabel() for ax in fig.axes[:3]] == ["x [m]", "y [m]", "theta [rad]"]


def test_scope_every_and_agents():
    res, s = unicycles(5, viz.Scope(["pose", "cmd"], every=4, agents=[1, 3]))
    rec = s.block.results
    assert np.allclose(rec["pose"], res["fleet.pose"][::4, [1, 3]])


def test_plot_signals_lines_for_few_agents():
    res, _ = unicycles(3)
    fig = viz.plot_signals(res, "fleet.pose", agents=[0, 2], components=[0])
    (ax,) = fig.axes
    lines = ax.get_lines()
    assert len(lines) == 2
    assert np.allclose(lines[1].get_ydata(), res["fleet.pose"][:, 2, 0])


def test_plot_signals_median_and_band_for_many():
    t = np.arange(4.0)
    y = np.tile(np.arange(100.0), (4, 1))[..., None] + t[:, None, None]
    res = av.Results(t, {"a.y": y})
    fig = viz.plot_signals(res, "a.y", max_lines=10)
    ax = fig.axes[0]
    (med,) = ax.get_lines()
    assert np.allclose(med.get_ydata(), np.median(y[..., 0], axis=1))
    bands = [c for c in ax.collections if isinstance(c, PolyCollection)]
    assert len(bands) == 2
    outer = bands[0].get_paths()[0].vertices[:, 1]
    assert np.isclose(outer.min(), np.percentile(y[0, :, 0], 5))
    assert np.isclose(outer.max(), np.percentile(y[-1, :, 0], 95))


def test_plot_trajectories(tmp_path):
    res, _ = unicycles(4)
    sq = Polygon([(0, 0), (1, 0), (1, 1), (0, 1)])
    fig = viz.plot_trajectories(res, world=[sq])
    ax = fig.axes[0]
    (lc,) = [c for c in ax.collections if isinstance(c, LineCollection)]
    segs = lc.get_segments()
    assert len(segs) == 4
    assert np.allclose(segs[2], res["fleet.pose"][:, 2, :2])
    assert len([c for c in ax.collections if isinstance(c, PathCollection)
                and len(c.get_paths()) == 1 and len(c.get_paths()[0]) == 5]) == 1
    fig.savefig(tmp_path / "traj.png")


def test_plot_signals_unknown_signal():
    res, _ = unicycles(2)
    with pytest.raises(KeyError, match="was not logged"):
        viz.plot_signals(res, "nope.y")
