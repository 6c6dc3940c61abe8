"""Angle helpers."""

from __future__ import annotations

import numpy as np


def wrap_angle(a, xp=np):
    """Wrap angles to the interval (-pi, pi].

    >>> float(wrap_angle(3 * np.pi))
    3.141592653589793
    >>> float(wrap_angle(-np.pi))
    3.141592653589793
    """
    return a - (2 * np.pi) * xp.ceil((a - np.pi) * (0.5 / np.pi))


def angle_diff(a, b, xp=np):
    """Smallest signed difference ``a - b`` wrapped to (-pi, pi]."""
    return wrap_angle(a - b, xp)
