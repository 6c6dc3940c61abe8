"""3D UAV view."""

import numpy as np
import pytest
from PIL import Image
from scipy.spatial.transform import Rotation

import avblocks as av
import avblocks.viz as viz


def test_quat_to_matrix_matches_scipy():
    q = np.random.default_rng(0).normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    ref = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()     # scipy: x, y, z, w
    assert np.allclose(viz.quat_to_matrix(q), ref)


def uav_results(T=6):
    t = np.arange(T) * 0.1
    p = np.zeros((T, 2, 3))
    p[:, 0] = [1.0, 2.0, 3.0]
    p[:, 1, 2] = 1.0 + t
    yaw = np.pi / 2
    q = np.tile([np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)], (T, 2, 1))
    return av.Results(t, {"uav.position": p, "uav.attitude": q})


def test_body_axes_follow_attitude():
    a = viz.animate3d(uav_results(), attitude="uav.attitude", drawing="axes", size=1.0,
                      figsize=(3, 3))
    a.update(0)
    segs = np.asarray(a.bodies._segments3d)          # (N * 3, 2, 3)
    x_axis = segs[0]
    assert np.allclose(x_axis[0], [1.0, 2.0, 3.0])
    assert np.allclose(x_axis[1] - x_axis[0], [0.0, 0.6, 0.0])   # body x -> world y
    assert np.allclose(segs[2, 1] - segs[2, 0], [0.0, 0.0, 0.6])  # body z stays up
    a.close()


def test_3d_movie_export(tmp_path):
    a = viz.animate3d(uav_results(T=6), trail=0.3, every=2, figsize=(2, 2), dpi=80)
    path = a.save(tmp_path / "uav.gif", fps=5)
    with Image.open(path) as im:
        assert im.n_frames == 3 and im.size == (160, 160)
    pytest.importorskip("imageio_ffmpeg")
    frames, _ = viz.read_video(a.save(tmp_path / "uav.mp4", fps=5))
    assert frames.shape == (3, 160, 160, 3)
    a.close()
