"""check_block (purity, shapes at N = 1 and 7, determinism, unmutated
inputs) on the MuJoCo and vision blocks; image ground texture."""

from __future__ import annotations

import numpy as np
import pytest

from avblocks.core.check import check_block

from ._mj import need

pytestmark = pytest.mark.mujoco


@pytest.fixture(scope="module")
def mods():
    need("mujoco")
    need("cv2")
    from avblocks.interfaces import mujoco as avmj
    from avblocks.interfaces import vision
    return avmj, vision


def _row(n, z=None):
    cols = [np.arange(n) * 1.0, np.zeros(n), np.zeros(n) if z is None else np.full(n, z)]
    return np.column_stack(cols)


def test_blocks_conform(mods):
    mj, vision = mods

    def ground(n):
        s = mj.Scene()
        s.add_ground_robots("r", _row(n))
        return mj.PhysicsWorld(s)

    def quad(n):
        s = mj.Scene()
        s.add_quadrotors("q", _row(n, 2.0), input="rotors")
        return mj.PhysicsWorld(s)

    def cam(n):
        s = mj.Scene(max_image=(32, 24))
        s.add_quadrotors("q", _row(n, 2.0), camera=mj.CameraMount())
        return mj.SceneCamera(s, "q", width=32, height=24)

    def est(n):
        K = vision.PinholeCamera.from_fov(60.0, 16, 12).K
        return vision.GroundPointEstimator(n, K, (0, 0, -0.05), mj.CameraMount().rotation())

    for factory in (ground, quad, cam, est,
                    lambda n: vision.ColorBlobTracker.red(n, 12, 16)):
        report = check_block(factory)
        assert report.ok, str(report)


def test_image_ground_texture(mods, tmp_path):
    """Scene(texture=<png>): the ground under a straight-down camera has the
    picture's colour (here a uniform blue-green picture)."""
    mj, _ = mods
    from PIL import Image
    png = tmp_path / "ground.png"
    Image.fromarray(np.full((16, 16, 3), (20, 140, 200), np.uint8)).save(png)
    s = mj.Scene(texture=str(png), ground_size=(-2, -2, 2, 2), max_image=(32, 24))
    s.add_camera("top", (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fovy=30.0)
    s.add_ground_robots("r", [[5.0, 5.0, 0.0]], kinematic=True)
    img = mj.SceneCamera(s, "top", width=32, height=24).render({"r_pose": [[5.0, 5.0, 0.0]]})
    r, g, b = img[0, 12, 16].astype(int)
    assert b > g > r and b - r > 80, (r, g, b)
