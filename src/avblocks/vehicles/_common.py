"""Small helpers shared by the vehicle models (parameter checks, limits)."""

from __future__ import annotations

import numpy as np

from ..core.errors import ParameterError
from ._rotations import dot


def limit(value, n, block, name, comp=()):
    """A per-agent limit: scalar, ``comp``-shaped, (N,) or (N, *comp); >= 0,
    ``inf`` meaning none. Returns a float array of shape ``(n, *comp)``."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError("limit must be numeric", block=block, param=name,
                             found=repr(value)[:80]) from None
    full = (n, *comp)
    if a.shape in ((), tuple(comp), full):
        a = np.broadcast_to(a, full).copy()
    else:
        raise ParameterError("wrong shape", block=block, param=name,
                             expected=f"a scalar, {tuple(comp) or '()'} or {full}",
                             found=a.shape)
    if np.any(np.isnan(a)) or np.any(a < 0):
        raise ParameterError("limit must be >= 0 (inf for none)", block=block,
                             param=name, expected=">= 0", found=np.nanmin(a))
    return a


def any_finite(*arrays):
    """True when any limit is finite (a clip is then needed)."""
    return bool(any(np.any(np.isfinite(a)) for a in arrays))


def clip_norm(vec, max_norm, xp=np):
    """Scale rows of ``vec`` (N, k) down to Euclidean norm ``<= max_norm`` (N,)."""
    nrm = xp.sqrt(dot(vec, vec))
    scale = xp.minimum(1.0, max_norm / xp.maximum(nrm, 1e-300))
    return vec * scale[:, None]
