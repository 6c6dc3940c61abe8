import os

import matplotlib

matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")
# The compiled engine's cache folder (avblocks.core.compiled.persist): one
# per test session, never the user's own. Compiled runs keep their XLA
# programs there by default, so a program compiled by one test (or the other
# xdist worker, which inherits the folder) is read, not compiled, by the
# next; the folder is new for each session (a CI run starts empty) and is
# deleted when the session that made it ends. Grown plans stay out of it
# (the fixture below): a plan grown in one test must not change another.
if "AVBLOCKS_CACHE_DIR" not in os.environ:
    import atexit
    import shutil
    import tempfile
    os.environ["AVBLOCKS_CACHE_DIR"] = tempfile.mkdtemp(prefix="avblocks-test-cache-")
    atexit.register(shutil.rmtree, os.environ["AVBLOCKS_CACHE_DIR"], ignore_errors=True)


import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _no_kept_plans():
    """Each test starts with an empty plan book of the compiled engine (a
    plan grown in one test must not change what another one sees: see
    avblocks.core.compiled.plans)."""
    from avblocks.core.compiled import plans  # no JAX import: only the plan book
    plans.forget_plans()
    plans.use_plan_store(False)     # grown plans in memory only (programs on disk)
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
