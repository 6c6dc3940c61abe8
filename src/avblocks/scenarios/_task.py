"""Pieces the learning-task scenarios (spread, pursuit, navigation) share.

Each task scenario builds its diagram around a vehicle block whose command
comes from one of three places (``controller=``):

- ``"scripted"``: the scenario's hand-written law (what ``avblocks run``
  shows);
- ``"action"``: an :class:`~avblocks.blocks.Action` block named ``action``
  (what :mod:`avblocks.rl` steps; actions in ``[-1, 1]`` per component);
- a path to a ``.npz`` policy (:class:`~avblocks.controllers.Policy`): the
  trained network reading the task block's ``obs``.

and a task block (``task``) computes, with ``xp``, the per-agent
observation ``obs``, the ``reward``, the per-agent ``done`` flag and the
``success`` measure from the vehicles' outputs, so a plain run logs the
same numbers an environment returns.
"""

from __future__ import annotations

import numpy as np


def others_index(n):
    """(n, n-1) int array: for agent i, the indices of the other agents."""
    idx = np.arange(n)
    return np.stack([np.delete(idx, i) for i in range(n)]) if n > 1 else \
        np.zeros((1, 0), dtype=int)


def pairwise(p, xp):
    """(n, n) distances between the rows of p (n, 2); diagonal = +inf."""
    d = p[:, None, :] - p[None, :, :]
    r = xp.sqrt(xp.sum(d * d, axis=-1) + 1e-12)
    n = p.shape[0]
    return xp.where(np.eye(n, dtype=bool), xp.inf, r)


def uniform_points(key, n, half, xp, min_sep=0.0, tries=8):
    """``n`` points uniform in ``[-half, half]^2`` (rng keys; both engines).
    With ``min_sep`` the draw is repeated ``tries`` times and the candidate
    with the largest closest-pair distance is kept (no loop on values, so
    it traces)."""
    from avblocks.core import rng
    ks = rng.split(key, xp, tries)
    best, best_d = None, None
    for k in ks:
        p = rng.uniform(k, (n, 2), xp, -half, half)
        if min_sep <= 0 or n < 2:
            return p
        d = xp.min(pairwise(p, xp))
        if best is None:
            best, best_d = p, d
        else:
            better = d > best_d
            best = xp.where(better, p, best)
            best_d = xp.where(better, d, best_d)
    return best


def command_source(d, controller, n, obs_ref, name="action"):
    """The block that drives the vehicles: Action or a trained Policy."""
    from avblocks.blocks import Action
    if controller == "action":
        return d.add(Action(n, 2, low=-1.0, high=1.0), name=name), "action"
    from avblocks.controllers import Policy
    pol = d.add(Policy.load(str(controller)), name=name)
    d.connect(obs_ref, pol.obs)
    return pol, "cmd"
