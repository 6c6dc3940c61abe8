"""Small helpers shared by the vehicle models (parameter checks, limits)."""

from __future__ import annotations

import numpy as np

from ..core.params import limit  # noqa: F401 - re-exported for the models
from ._rotations import dot


def any_finite(*arrays):
    """True when any limit is finite (a clip is then needed)."""
    return bool(any(np.any(np.isfinite(a)) for a in arrays))


def clip_norm(vec, max_norm, xp=np):
    """Scale rows of ``vec`` (N, k) down to Euclidean norm ``<= max_norm`` (N,).

    A zero row stays zero; its gradient is finite too (the square root is
    taken of 1 there, not of 0, whose derivative is infinite: a gradient
    through a run where an agent stops exactly would otherwise be NaN)."""
    n2 = dot(vec, vec)
    moving = n2 > 0
    nrm = xp.sqrt(xp.where(moving, n2, 1.0))
    scale = xp.where(moving, xp.minimum(1.0, max_norm / nrm), 1.0)
    return vec * scale[:, None]
