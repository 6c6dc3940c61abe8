"""Angle helpers."""

from __future__ import annotations

import numpy as np

from ..core.memo import compute_once


def wrap_angle(a, xp=np):
    """Wrap angles to the interval (-pi, pi].

    >>> float(wrap_angle(3 * np.pi))
    3.141592653589793
    >>> float(wrap_angle(-np.pi))
    3.141592653589793
    """
    return a - (2 * np.pi) * xp.ceil((a - np.pi) * (0.5 / np.pi))


def heading_trig(pose, xp=np):
    """``(cos theta, sin theta)`` of the headings ``pose[:, 2]`` of poses (N, >= 3).

    Vehicles and controllers of the unicycle family call it through
    :func:`avblocks.core.memo.shared`, so that inside a simulator the trig of
    one pose array is taken once however many blocks need it.

    >>> c, s = heading_trig(np.array([[0.0, 0.0, np.pi / 2]]))
    >>> float(c[0]) < 1e-15, float(s[0])
    (True, 1.0)
    """
    th = pose[:, 2]
    return compute_once((xp.cos(th), xp.sin(th)), xp)


def angle_diff(a, b, xp=np):
    """Smallest signed difference ``a - b`` wrapped to (-pi, pi]."""
    return wrap_angle(a - b, xp)
