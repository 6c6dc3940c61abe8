"""ColorBlobTracker against independent pixel counts; pinhole geometry round
trips; the tracker on real MuJoCo renders against the projected truth."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import avblocks as av
from avblocks.interfaces.vision import (
    ColorBlobTracker,
    GroundPointEstimator,
    PinholeCamera,
    camera_pose,
    pinhole,
)

from ._mj import need

pytestmark = pytest.mark.vision


@pytest.fixture(scope="module")
def cv2():
    return need("cv2")


def _disc(img, cx, cy, r, rgb):
    h, w = img.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    m = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
    img[m] = rgb
    return m


def test_largest_blob_centroid_area_bbox(cv2):
    """Three images in one call: two red discs (the larger wins), a red of
    hue ~175 (wrapping) next to a green one, and nothing red."""
    imgs = np.full((3, 60, 80, 3), 90, np.uint8)
    _disc(imgs[0], 20, 20, 4, (230, 20, 20))
    big = _disc(imgs[0], 55.3, 35.7, 9, (230, 20, 20))
    wrap = _disc(imgs[1], 40, 30, 6, (230, 20, 60))      # hue ~ 170-175 (magenta-red)
    _disc(imgs[1], 10, 10, 12, (20, 230, 20))
    hsv = cv2.cvtColor(imgs[1, 30:31, 40:41], cv2.COLOR_RGB2HSV)[0, 0]
    assert hsv[0] > 170                                  # really on the wrapped side
    tr = ColorBlobTracker.red(3, 60, 80)
    y = tr.output(0.0, {}, {"image": imgs}, np)
    assert y["found"].tolist() == [True, True, False]
    for k, m in ((0, big), (1, wrap)):
        rows, cols = np.nonzero(m)
        assert y["centroid"][k] == pytest.approx([cols.mean(), rows.mean()], abs=1e-9)
        assert y["area"][k] == m.sum()
        assert y["bbox"][k].tolist() == [cols.min(), rows.min(), np.ptp(cols) + 1,
                                         np.ptp(rows) + 1]
    assert y["centroid"][2].tolist() == [0.0, 0.0] and y["area"][2] == 0


def test_hue_interval_without_wrap_and_min_area(cv2):
    imgs = np.full((1, 40, 40, 3), 90, np.uint8)
    _disc(imgs[0], 10, 10, 1, (20, 230, 20))             # 5 px green
    m = _disc(imgs[0], 30, 25, 5, (20, 20, 230))         # blue
    blue = ColorBlobTracker(1, 40, 40, lower=(100, 120, 70), upper=(130, 255, 255))
    y = blue.output(0.0, {}, {"image": imgs}, np)
    rows, cols = np.nonzero(m)
    assert y["found"][0] and y["centroid"][0] == pytest.approx([cols.mean(), rows.mean()])
    green = ColorBlobTracker(1, 40, 40, lower=(50, 120, 70), upper=(70, 255, 255), min_area=6)
    assert not green.output(0.0, {}, {"image": imgs}, np)["found"][0]


def test_tracker_errors(cv2):
    with pytest.raises(av.AvError, match="HSV"):
        ColorBlobTracker(1, 10, 10, lower=(200, 0, 0))
    tr = ColorBlobTracker.red(2, 10, 10)
    with pytest.raises(av.AvError, match="wrong shape"):
        tr.output(0.0, {}, {"image": np.zeros((1, 10, 10, 3), np.uint8)}, np)


def _random_rotation(rng, n):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return av.vehicles._rotations.quat_to_rotmat(q)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_pixel_ground_projection_round_trip(seed):
    rng = np.random.default_rng(seed)
    cam = PinholeCamera.from_fov(rng.uniform(30, 100), 320, 240)
    n = 16
    R = _random_rotation(rng, n)
    c = rng.uniform(-5, 5, size=(n, 3))
    c[:, 2] = rng.uniform(0.5, 10, size=n)
    px = rng.uniform([0, 0], [319, 239], size=(n, 2))
    p, ok = cam.pixel_to_ground(px, c, R)
    back, front = cam.project(p[ok], c[ok], R[ok])
    assert np.all(front)
    assert np.allclose(back, px[ok], atol=1e-6)
    assert np.allclose(p[ok, 2], 0.0)
    # rays pointing up never hit the ground, and say so
    d = cam.pixel_to_ray(px, R)
    assert np.array_equal(ok, d[:, 2] < 0)
    assert np.all(np.isnan(p[~ok]))


def test_projection_against_opencv(cv2):
    """project() against cv2.projectPoints (an implementation we didn't write)."""
    rng = np.random.default_rng(5)
    cam = PinholeCamera.from_fov(55.0, 640, 480)
    R = _random_rotation(rng, 1)[0]
    c = np.array([1.0, -2.0, 3.0])
    pts = c + rng.normal(size=(50, 3)) * 3
    pc = (pts - c) @ R
    pts = pts[pc[:, 2] > 0.5]
    ours, _ = cam.project(pts, c[None], R[None])
    rvec, _ = cv2.Rodrigues(R.T)
    tvec = -R.T @ c
    ref, _ = cv2.projectPoints(pts, rvec, tvec, cam.K, None)
    assert np.allclose(ours, ref[:, 0], atol=1e-6)


def test_tracker_on_rendered_frames_within_one_pixel(cv2):
    """A red car (no heading mark) under the quadrotor's downward camera at
    several offsets and attitudes: the blob centroid is within 1 px of the
    projection of the car's true centre (its centre of volume)."""
    need("mujoco")
    from avblocks.interfaces import mujoco as avmj
    s = avmj.Scene(texture="checker")
    s.add_ground_robots("car", [[0.0, 0.0, 0.0]], radius=0.2, height=0.1,
                        color=(0.85, 0.05, 0.05), marker=False, kinematic=True)
    mount = avmj.CameraMount(fovy=60.0)
    s.add_quadrotors("uav", [[0.0, 0.0, 4.0]], camera=mount, kinematic=True)
    cam = avmj.SceneCamera(s, "uav", width=160, height=120)
    tr = ColorBlobTracker.red(1, 120, 160)
    rng = np.random.default_rng(11)
    errs = []
    for _ in range(12):
        car = np.array([[*rng.uniform(-1.2, 1.2, 2), rng.uniform(-3, 3)]])
        q = av.vehicles._rotations.quat_from_euler(
            rng.uniform(-0.15, 0.15, 1), rng.uniform(-0.15, 0.15, 1), rng.uniform(-3, 3, 1))
        u = {"car_pose": car, "uav_position": np.array([[0.1, -0.2, 4.0]]),
             "uav_attitude": q}
        img = cam.output(0.0, {}, u, np)["image"]
        y = tr.output(0.0, {}, {"image": img}, np)
        assert y["found"][0]
        pos, R = camera_pose(u["uav_position"], q, mount.pos, mount.rotation())
        centre = np.array([[car[0, 0], car[0, 1], 0.05]])
        truth, front = pinhole.project(centre, cam.K[0], pos, R)
        errs.append(np.linalg.norm(y["centroid"][0] - truth[0]))
    assert max(errs) < 1.0, errs
    print("max centroid error px", max(errs))


def test_ground_point_estimator_inverts_projection():
    rng = np.random.default_rng(2)
    mount_pos, mount_rot = np.array([0.0, 0.0, -0.05]), np.array(
        [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    cam = PinholeCamera.from_fov(60.0, 160, 120)
    est = GroundPointEstimator(4, cam.K, mount_pos, mount_rot, z0=0.05)
    pos = rng.uniform(-2, 2, (4, 3))
    pos[:, 2] = 4.0
    q = av.vehicles._rotations.quat_from_euler(*rng.uniform(-0.2, 0.2, (3, 4)))
    target = np.column_stack([pos[:, :2] + rng.uniform(-1, 1, (4, 2)), np.full(4, 0.05)])
    c, R = camera_pose(pos, q, mount_pos, mount_rot)
    px, _ = pinhole.project(target, cam.K, c, R)
    u = {"centroid": px, "found": np.array([True, True, True, False]), "position": pos,
         "attitude": q}
    x = est.initial_state()
    y = est.output(0.0, x, u, np)
    assert np.allclose(y["point"][:3], target[:3], atol=1e-9)
    assert y["valid"].tolist() == [True, True, True, False]
    assert np.array_equal(y["point"][3], [0.0, 0.0, 0.0])     # held (initial)
    x = est.update(0.0, x, u, np, y)
    assert np.allclose(x["last"][:3], target[:3])
