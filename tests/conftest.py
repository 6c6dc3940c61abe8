import os

import matplotlib

matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")
# the compiled engine's cache (programs and grown plans) of the CLI runs the
# tests start: never the user's own folder
os.environ.setdefault("AVBLOCKS_CACHE_DIR", __import__("tempfile").mkdtemp(
    prefix="avblocks-test-cache-"))


import sys  # noqa: E402

import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _no_kept_plans():
    """Each test starts with an empty plan book of the compiled engine (a
    plan grown in one test must not change what another one sees: see
    avblocks.core.compiled.plans)."""
    plans = sys.modules.get("avblocks.core.compiled.plans")
    if plans is not None:
        plans.forget_plans()
        plans.use_plan_store(None)      # a CLI run in this process may have turned it on
    yield


@pytest.fixture
def mujoco_extra():
    """MuJoCo through avblocks (which picks a headless GL before importing
    it) and OpenCV, or skip (a case study that needs them, e.g. uav_tracking);
    in CI (``CI`` set) a missing part fails instead."""
    try:
        from avblocks.interfaces.mujoco import import_mujoco
        import_mujoco()
        import cv2  # noqa: F401
    except ImportError as e:
        if os.environ.get("CI"):
            raise
        pytest.skip(f"mujoco or cv2 unavailable: {e}")
