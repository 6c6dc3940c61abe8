"""Lab 7: learning to navigate. Write `observe` and `reward` (the library's
navigation task, avblocks.tasks.NavigationTask), train a policy on them,
embed it here (POLICY, below), then run `avblocks lab check 7
lab7_learning.py` (its last check needs the ros2 extra: pip install
'avblocks[ros2]').

N agents (single integrators) go to their goals in a 3 m square arena with
three boxes, sensing with 12 range rays, without touching anything.

observe: what agent i sees, one row per agent, 4 + R + 2 (N - 1) numbers:

    [ g_i - p_i,                 the goal relative to the agent   (2)
      p_i / half,                the own position, normalised      (2)
      ranges_i / max_range,      the R range rays, normalised      (R)
      p_j - p_i for j != i ]     the other agents relative to it, nearest
                                 first (by |p_j - p_i|)            (2 (N-1))

reward: what agent i earns at a step, with d_i = |g_i - p_i|, prev_i the
distance at the previous step, contact_i "touching now", hit_i "touched
before in this episode":

    progress (prev_i - d_i)
    + goal_bonus [d_i < goal_radius]
    + success_bonus [d_i < goal_radius and not (hit_i or contact_i)]
    - first_hit [contact_i and not hit_i]
    - collision [contact_i]
    - proximity closeness_i

closeness_i = sum over the other agents j of clip(1 - gap_ij / margin, 0, 1),
gap_ij = |p_i - p_j| - 2 radius, plus the same for the nearest obstacle or
wall, gap = clearance_i - radius (clearance_i: the distance from the
agent's centre to the nearest obstacle or wall edge, given).

policy: the trained actor's weights, embedded below by
avblocks.labs.lab7_learning.embed_policy (see the lab page).

Rules of the library: the agent axis comes first, compute with `xp` (the
training traces your functions with JAX: no Python `if` on array values,
no loop over agents), never write into the inputs, and take N from the
inputs: the same functions serve teams of any size.
"""

import base64
import io

import numpy as np


def observe(position, goals, ranges, half, max_range, xp=np):
    """(N, 4 + R + 2 (N - 1)) observations.

    position, goals (N, 2) [m]; ranges (N, R) [m]; half: half the arena's
    side [m]; max_range: the range sensor's reach [m].
    """
    # TODO: the four parts above, concatenated along the last axis
    raise NotImplementedError("write observe")


def reward(position, goals, prev, contact, hit, clearance, params, xp=np):
    """(N,) rewards.

    position, goals (N, 2) [m]; prev (N,) [m]; contact, hit (N,) bool;
    clearance (N,) [m]; params: a dict with radius, goal_radius, margin and
    the weights progress, goal_bonus, success_bonus, first_hit, collision,
    proximity.
    """
    # TODO: the six terms above, for every agent at once
    raise NotImplementedError("write reward")


# The trained weights: base64 of an .npz, written by embed_policy (do not edit by hand).
POLICY = """
"""


def policy():
    """The trained policy's weights {"w0": ..., "b0": ..., ...}, from POLICY."""
    if not POLICY.strip():
        raise NotImplementedError("write POLICY: train the policy and embed it with "
                                  "avblocks.labs.lab7_learning.embed_policy (the lab page)")
    raw = base64.b64decode("".join(POLICY.split()))
    with np.load(io.BytesIO(raw), allow_pickle=False) as z:
        return {k: z[k] for k in z.files}
