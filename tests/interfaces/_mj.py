"""Shared set-up for the MuJoCo and vision tests: skip only off CI."""

from __future__ import annotations

import os

import pytest


def need(module):
    """Import ``module`` (avblocks.interfaces.mujoco / vision extras) or skip;
    in CI (``CI`` set) a missing part fails instead of skipping."""
    try:
        if module == "mujoco":
            from avblocks.interfaces.mujoco import choose_backend, import_mujoco
            import_mujoco()
            return choose_backend()
        if module == "cv2":
            import cv2
            return cv2
        raise ValueError(module)
    except ImportError as e:
        if os.environ.get("CI"):
            raise
        pytest.skip(f"{module} unavailable: {e}")
