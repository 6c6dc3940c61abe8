"""SceneCamera: real renders, intrinsics checked against MuJoCo's own ray
casting, camera rate."""

from __future__ import annotations

import numpy as np
import pytest

import avblocks as av
from avblocks.interfaces.vision import pinhole
from avblocks.vehicles import Unicycle

from ._mj import need

pytestmark = pytest.mark.mujoco


@pytest.fixture(scope="module")
def mj():
    need("mujoco")
    from avblocks.interfaces import mujoco as avmj
    return avmj


def _scene(mj):
    s = mj.Scene(texture=None)
    s.add_ground_robots("cars", [[1.0, 0.5, 0.3], [-1.0, -0.5, 0.0]], radius=0.2,
                        color=(0.9, 0.05, 0.05), marker=False)
    s.add_quadrotors("uav", [[0.0, 0.0, 4.0]], camera=mj.CameraMount(fovy=60.0))
    s.add_camera("top", (0.5, -6.0, 7.0), (0.0, 0.0, 0.0), fovy=50.0)
    return s


def _inputs(yaw=0.4, tilt=0.1):
    q = av.vehicles._rotations.quat_from_euler(np.array([tilt]), np.array([-0.05]),
                                               np.array([yaw]))
    return {"cars_pose": np.array([[1.0, 0.5, 0.3], [-1.0, -0.5, 0.0]]),
            "uav_position": np.array([[0.2, -0.1, 4.0]]), "uav_attitude": q}


def test_image_port_and_pixels(mj):
    s = _scene(mj)
    cam = mj.SceneCamera(s, ["uav0_cam", "top"], width=160, height=120)
    assert cam.output_ports["image"].shape == (2, 120, 160, 3)
    assert cam.output_ports["image"].dtype == "uint8"
    u = _inputs()
    img = cam.output(0.0, {}, u, np)["image"]
    assert img.shape == (2, 120, 160, 3) and img.dtype == np.uint8
    pos, R = cam.camera_poses(u)
    for c in range(2):
        # the projected centre of the car's top face is red, a ground point
        # 1.5 m away from both cars is not
        top = np.array([[1.0, 0.5, 0.2]])
        px, front = pinhole.project(top, cam.K[c], pos[c:c + 1], R[c:c + 1])
        assert front[0]
        col, row = np.round(px[0]).astype(int)
        r, g, b = img[c, row, col].astype(int)
        assert r > 120 and g < 60 and b < 60, (c, img[c, row, col])
        px, _ = pinhole.project(np.array([[0.0, 1.8, 0.0]]), cam.K[c], pos[c:c + 1],
                                R[c:c + 1])
        col, row = np.round(px[0]).astype(int)
        r, g, b = img[c, row, col].astype(int)
        assert abs(r - g) < 30, (c, img[c, row, col])         # grey ground


def test_camera_matrix_against_mujoco_ray_casting(mj):
    """pixel -> ray (our K and camera pose) hits the ground where MuJoCo's own
    ray caster (mj_ray) says, and projecting MuJoCo's hit gives the pixel back."""
    mujoco = mj.import_mujoco()
    s = _scene(mj)
    cam = mj.SceneCamera(s, ["uav0_cam", "top"], width=160, height=120)
    u = _inputs()
    d = cam.pose_data(u)
    pos, R = cam.camera_poses(u)
    rng = np.random.default_rng(3)
    pixels = rng.uniform([0, 0], [159, 119], size=(20, 2))
    for c in range(2):
        K = cam.camera_matrix(c)
        rays = pinhole.pixel_to_ray(pixels, K, np.repeat(R[c:c + 1], 20, 0))
        ours, ok = pinhole.ray_ground(np.repeat(pos[c:c + 1], 20, 0), rays)
        geomid = np.zeros(1, np.int32)
        gid = mujoco.mj_name2id(s.model, mujoco.mjtObj.mjOBJ_GEOM, "ground")
        n_ground = 0
        for k in range(20):
            dist = mujoco.mj_ray(s.model, d, pos[c], rays[k], None, 1, -1, geomid)
            if geomid[0] != gid:
                continue            # a car or the drone is in the way
            n_ground += 1
            hit = pos[c] + dist * rays[k]
            assert ok[k]
            assert np.allclose(hit, ours[k], atol=1e-6)
            back, front = pinhole.project(hit[None], K, pos[c:c + 1], R[c:c + 1])
            assert front[0] and np.allclose(back[0], pixels[k], atol=1e-6)
        assert n_ground >= 15


def test_camera_rate_and_hold(mj):
    """A camera with period 0.05 s in a diagram stepped at 0.01 s renders only
    at its hits and holds the image in between."""
    s = mj.Scene(texture=None)
    s.add_ground_robots("cars", [[0.0, 0.0, 0.0]], color=(0.9, 0.05, 0.05), marker=False)
    s.add_camera("top", (0.0, 0.0, 6.0), (0.0, 0.0, 0.0))
    d = av.Diagram()
    car = d.add(Unicycle([[-1.0, 0.0, 0.0]]), name="car")
    c = d.add(av.blocks.Constant(np.array([[1.0, 0.0]])), name="cmd")
    block = mj.SceneCamera(s, "top", width=64, height=48, period=0.05)
    cam = d.add(block, name="cam")
    d.connect(c.y, car.cmd)
    d.connect(car.pose, cam.cars_pose)
    calls = []
    render = block.render
    block.render = lambda u: (calls.append(1), render(u))[1]
    res = av.simulate(d, 0.5, dt=0.01, log=["cam.image", "car.pose"], progress=False)
    imgs = res["cam.image"]
    assert imgs.shape == (51, 1, 48, 64, 3)
    assert 11 <= len(calls) <= 12                  # t = 0, 0.05, ..., 0.5 (+ initial)
    for k in range(51):                            # held between hits
        assert np.array_equal(imgs[k], imgs[5 * (k // 5)])
    assert not np.array_equal(imgs[0], imgs[5])    # the car moved 5 cm


def test_bad_camera_arguments(mj):
    s = _scene(mj)
    with pytest.raises(av.AvError, match="unknown camera"):
        mj.SceneCamera(s, "nope")
    with pytest.raises(av.AvError, match="offscreen"):
        mj.SceneCamera(s, "top", width=2000, height=100)
    with pytest.raises(av.AvError, match="no cameras"):
        mj.SceneCamera(s, "cars")
