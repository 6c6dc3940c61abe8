"""Diagrams the analysis tests share, and their closed forms."""

from __future__ import annotations

import numpy as np

import avblocks as av


def formation_steady_poses(leader, l_ref, alpha_ref, d, lead_pose):
    """Poses of a leader-follower formation in its steady state behind a
    leader driving straight (eq. 2 solved for the follower): every agent
    has the leader's heading, and follower i's off-axis point sits at
    distance l_ref[i], tracking angle alpha_ref[i] from its leader:
    ``x_d = p_lead - l (cos(theta + alpha), sin(theta + alpha))``,
    ``p = x_d - d (cos theta, sin theta)``."""
    n = len(leader)
    pose = np.zeros((n, 3))
    pose[0] = lead_pose
    for i in range(1, n):           # leaders come before their followers here
        lp = pose[leader[i]]
        th = lp[2]
        z = th + alpha_ref[i]
        xd = lp[:2] - l_ref[i] * np.array([np.cos(z), np.sin(z)])
        pose[i, :2] = xd - d * np.array([np.cos(th), np.sin(th)])
        pose[i, 2] = th
    return pose


#: a leader and three followers (a star and a chain of two)
LEADER = [-1, 0, 0, 1]
L_REF = [0.0, 1.0, 1.2, 0.8]
ALPHA_REF = [0.0, 0.5, -0.4, 0.2]
D = 0.1
K_L = np.array([1.0, 1.5, 0.7, 2.0])
K_ALPHA = np.array([1.0, 0.9, 2.5, 1.3])


def formation(v0=0.8, pose=None, references_input=False):
    """The paper's leader-follower formation (eqs. 2-5): unicycles, a
    constant leader command ``(v0, 0)``, followers at their steady state."""
    if pose is None:
        pose = formation_steady_poses(LEADER, L_REF, ALPHA_REF, D, [0.3, -0.2, 0.4])
    d = av.Diagram()
    fleet = d.add(av.vehicles.Unicycle(pose0=pose), name="fleet")
    lead = d.add(av.blocks.Constant(np.tile([v0, 0.0], (4, 1))), name="lead")
    if references_input:
        form = d.add(av.controllers.LeaderFollower(LEADER, d=D, k_l=K_L, k_alpha=K_ALPHA,
                                                   references_input=True), name="form")
        ref = d.add(av.blocks.Constant(np.column_stack([L_REF, ALPHA_REF])), name="ref")
        d.connect(ref.y, form.ref)
    else:
        form = d.add(av.controllers.LeaderFollower(LEADER, l_ref=L_REF, alpha_ref=ALPHA_REF,
                                                   d=D, k_l=K_L, k_alpha=K_ALPHA),
                     name="form")
    d.connect(fleet.pose, form.pose)
    d.connect(lead.y, form.cmd_in)
    d.connect(form.cmd, fleet.cmd)
    return d


def ring_adjacency(n):
    ring = np.roll(np.eye(n), 1, axis=1)
    return ring + ring.T


def consensus_ring(n=8, gain=0.7, seed=2):
    d = av.Diagram()
    agents = d.add(av.vehicles.SingleIntegrator(
        position0=np.random.default_rng(seed).normal(size=(n, 2))), name="agents")
    law = d.add(av.controllers.Consensus(n, gain=gain, adjacency=ring_adjacency(n)),
                name="law")
    d.connect(agents.position, law.position)
    d.connect(law.velocity, agents.velocity)
    return d
