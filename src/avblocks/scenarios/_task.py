"""Pieces the learning-task scenarios (spread, pursuit, navigation) share.

Each task scenario builds its diagram around a vehicle block whose command
comes from one of three places (``controller=``):

- ``"scripted"``: the scenario's hand-written law (what ``avblocks run``
  shows);
- ``"action"``: an :class:`~avblocks.blocks.Action` block named ``action``
  (what :mod:`avblocks.rl` steps; actions in ``[-1, 1]`` per component);
- a path to a ``.npz`` policy (:class:`~avblocks.controllers.Policy`): the
  trained network reading the task block's ``obs``.

and a task block (``task``, from :mod:`avblocks.tasks`) computes, with
``xp``, the per-agent observation ``obs``, the ``reward``, the per-agent
``done`` flag and the ``success`` measure from the vehicles' outputs, so a
plain run logs the same numbers an environment returns. The array helpers
live beside the task blocks (:mod:`avblocks.tasks.common`) and are
re-exported here.
"""

from __future__ import annotations

from avblocks.tasks.common import (  # noqa: F401  (re-exported)
    RANK_SORT_MAX,
    drop_diagonal,
    free_points,
    others_index,
    pairwise,
    sort_rows,
    uniform_points,
)


def drive_at_speed(d, cmd, velocity, speed):
    """Wire ``cmd`` (unit commands) through a ``speed`` gain into the
    vehicles' ``velocity`` input: the last link of every task scenario.
    Returns the gain's handle (its ``y``: the velocity commands)."""
    from avblocks.blocks import Gain
    gain = d.add(Gain(float(speed)), name="speed")
    d.connect(cmd, gain.u)
    d.connect(gain.y, velocity)
    return gain


def command_source(d, controller, n, obs_ref, name="action"):
    """The block that drives the vehicles: Action or a trained Policy."""
    from avblocks.blocks import Action
    if controller == "action":
        return d.add(Action(n, 2, low=-1.0, high=1.0), name=name), "action"
    from avblocks.controllers import Policy
    pol = d.add(Policy.load(str(controller)), name="policy")
    d.connect(obs_ref, pol.obs)
    return pol, "cmd"
