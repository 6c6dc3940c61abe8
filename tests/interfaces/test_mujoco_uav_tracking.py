"""Case study IV.C: a quadrotor tracks a red ground vehicle by its camera.

Error bound (horizontal distance drone - vehicle), stated and justified:
the tracking controller feeds the filtered target velocity forward, so on
straight legs the error decays to ~0; at a waypoint the vehicle's velocity
changes by at most 2V (a U-turn) and the drone answers after the velocity
loop's time constant 1/k_v = 0.4 s plus one camera period T = 0.1 s, so the
error peaks at about 2 V (1/k_v + T) = 0.8 m at V = 0.8 m/s; 0.2 m more
covers the start (the drone starts 0.72 m off) and the image shift from the
drone's tilt. B = 1.0 m, well inside the camera's ground footprint
(half-height 4 m tan(30 deg) = 2.3 m), so the vehicle also stays in view.
"""

from __future__ import annotations

import numpy as np
import pytest

import avblocks as av

from ._mj import need

pytestmark = pytest.mark.mujoco

BOUND = 2 * 0.8 * (1 / 2.5 + 0.1) + 0.2


@pytest.fixture(scope="module")
def ut():
    need("mujoco")
    need("cv2")
    from avblocks.scenarios import uav_tracking
    return uav_tracking


@pytest.mark.slow
@pytest.mark.parametrize("physics", ["mujoco", "model"])
def test_drone_keeps_the_vehicle_in_view(ut, physics):
    d, sim = ut.make_diagram(t_final=12.0, physics=physics, scene_view=False)
    res = av.simulate(d, progress=False, **sim)
    assert res["camera.image"].shape == (121, 1, 120, 160, 3)
    err = ut.tracking_error(res)
    vis, px = ut.in_view(res, 160, 120)
    found = res["tracker.found"][:, 0]
    assert vis.all() and found.all()
    assert err.max() < BOUND, err.max()
    assert np.sqrt(np.mean(err ** 2)) < 0.5
    # the vehicle really drove (so the drone really followed)
    tp = res["target.pose"][:, 0, :2]
    assert np.sum(np.linalg.norm(np.diff(tp, axis=0), axis=1)) > 7.0
    # the tracked centroid is the projection of the vehicle's true centre
    # (within 1 px) in every rendered frame
    dev = np.linalg.norm(res["tracker.centroid"][:, 0] - px, axis=1)
    assert dev.max() < 1.0, dev.max()


def test_report_writes_plot_and_movie(ut, tmp_path):
    d, sim = ut.make_diagram(t_final=1.0, view_size=(160, 120))
    res = av.simulate(d, progress=False, **sim)
    files, line = ut.report(res, tmp_path)
    names = sorted(p.name for p in files)
    assert "tracking_error.png" in names
    assert line.startswith("tracking: max horizontal error")
    if "tracking.mp4" in names:
        from avblocks.viz.movie import read_video
        frames, fps = read_video(tmp_path / "tracking.mp4")
        assert frames.shape[0] == 11 and fps == pytest.approx(10.0)
        assert frames.shape[2] >= 160 + 4 + 160
