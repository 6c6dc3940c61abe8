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

    Differentiable everywhere it is finite: rows within the limit (always the
    case for ``max_norm = inf``) get scale 1 through a double ``where`` whose
    other branch only ever sees finite numbers (``max_norm / nrm`` with
    ``max_norm = inf`` or ``nrm = 0`` would put ``0 * inf = NaN`` into the
    gradient of a traced run).
    """
    sq = dot(vec, vec)
    over = sq > max_norm * max_norm
    nrm = xp.sqrt(xp.where(over, sq, 1.0))
    scale = xp.where(over, xp.where(over, max_norm, 1.0) / nrm, 1.0)
    return vec * scale[:, None]
