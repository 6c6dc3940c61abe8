"""Small helpers shared by the vehicle models (parameter checks, limits)."""

from __future__ import annotations

import numpy as np

from ..core.params import limit  # noqa: F401 - re-exported for the models
from ._rotations import dot


def any_finite(*arrays):
    """True when any limit is finite (a clip is then needed)."""
    return bool(any(np.any(np.isfinite(a)) for a in arrays))


def clip_norm(vec, max_norm, xp=np):
    """Scale rows of ``vec`` (N, k) down to Euclidean norm ``<= max_norm`` (N,)."""
    nrm = xp.sqrt(dot(vec, vec))
    scale = xp.minimum(1.0, max_norm / xp.maximum(nrm, 1e-300))
    return vec * scale[:, None]
