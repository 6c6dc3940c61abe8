r"""Leader following by feedback linearization (AVLib paper eqs. (2)-(5)).

Equations
---------
Follower ``n`` (pose ``x_n, y_n, theta_n``) tracks its leader ``0`` (pose
``x_0, y_0, theta_0``, velocities ``v_0, omega_0``) through its off-axis point
``x_n^d = x_n + d cos theta_n``, ``y_n^d = y_n + d sin theta_n``:

.. math::

    l_n = \sqrt{(x_0 - x_n^d)^2 + (y_0 - y_n^d)^2},\quad
    \alpha_n = \zeta_n - \theta_0,\quad \beta_n = \zeta_n - \theta_n,\quad
    \zeta_n = \operatorname{atan2}(y_0 - y_n^d, x_0 - x_n^d)            \tag{2}

    s_n = [l_n, \alpha_n]^T                                           \tag{3}

    [v_n, \omega_n]^T = F^{-1}\Big([u_{nl}, u_{n\alpha}]^T
        - \begin{bmatrix}\cos\alpha_n & 0\\ -\sin\alpha_n / l_n & -1\end{bmatrix}
          [v_0, \omega_0]^T\Big)                                        \tag{4}

    F^{-1} = \begin{bmatrix} -\cos\beta_n & l_n\sin\beta_n\\
             -\sin\beta_n / d & -l_n\cos\beta_n / d\end{bmatrix}        \tag{5}

with ``u_nl = K_l (l_ref - l_n)`` and ``u_na = K_alpha wrap(alpha_ref - alpha_n)``.
Then ``dl/dt = u_nl`` and ``dalpha/dt = u_na``: both errors decay as
``exp(-K t)``.

**Sign of the (2, 2) entry.** The paper prints ``+1`` in the lower right of the
drift matrix in (4). Differentiating (2) gives
``dalpha/dt = (v_n sin beta - d omega_n cos beta - v_0 sin alpha) / l - omega_0``,
i.e. ``ds/dt = F [v_n, omega_n]^T + D [v_0, omega_0]^T`` with
``D = [[cos alpha, 0], [-sin alpha / l, -1]]`` and ``F`` the inverse of (5)
(which the paper prints correctly). With ``+1`` the closed loop would be
``dalpha/dt = u_na - 2 omega_0``: a steady tracking-angle error
``-2 omega_0 / K_alpha`` whenever the leader turns. This module uses ``-1``
(tested against finite differences of (2)); everything else is as printed.

**Angles.** ``alpha_n`` is wrapped to (-pi, pi] as in the paper and the error
``alpha_ref - alpha_n`` is wrapped too (identical to the paper's difference
unless it crosses +-pi, where the wrapped one turns the short way).
``alpha = 0`` puts the follower's point straight behind the leader; a point
on the leader's left has ``alpha < 0``.

**Singular cases.** ``d`` must be > 0 (``F`` is singular at ``d = 0``; a
ParameterError says so). As ``l -> 0`` the bearing ``zeta`` is undefined and
the feed-forward term ``sin(alpha) / l`` blows up: the block divides by
``max(l, l_min)`` instead (``l_min`` a parameter, default 1e-3 m), and at
``l = 0`` exactly it uses ``zeta = atan2(0, 0) = 0``. ``F^{-1}`` itself is
bounded as ``l -> 0`` and is used as printed.

**Leader velocities.** ``(v_0, omega_0)`` are the leader's *commanded*
velocities (exact for first-order unicycles without saturation).

Reference: "AVLib: A Simulink Library for Multi-Agent Systems Research"
(the AVLib paper), Section III.B, eqs. (2)-(5); A. K. Das et al., "A
vision-based formation control framework", IEEE TRA 18(5), 2002 (l-psi
control).
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.memo import shared
from ..core.params import agent_array, positive_scalar
from ..utility.angles import heading_trig, wrap_angle


def leader_follower_terms(pose, pose_l, l_ref, alpha_ref, d, k_l, k_alpha,
                          l_min=1e-3, xp=np):
    """Affine form of eq. (4): ``[v, omega] = a + M [v_0, omega_0]``.

    ``pose`` (N, 3) followers, ``pose_l`` (N, 3) their leaders; parameters
    scalars or (N,). Returns ``a`` (N, 2), ``M`` (N, 2, 2), ``s = (l, alpha)``
    (N, 2) and the errors ``(l_ref - l, wrap(alpha_ref - alpha))`` (N, 2).
    """
    th = pose[:, 2]
    c, s = shared(heading_trig, pose, xp)     # shared with the vehicle's model
    xd = pose[:, 0] + d * c
    yd = pose[:, 1] + d * s
    dx = pose_l[:, 0] - xd
    dy = pose_l[:, 1] - yd
    l = xp.sqrt(dx * dx + dy * dy)
    zeta = xp.arctan2(dy, dx)
    alpha = wrap_angle(zeta - pose_l[:, 2], xp)
    beta = wrap_angle(zeta - th, xp)
    e_l = l_ref - l
    e_a = wrap_angle(alpha_ref - alpha, xp)
    u_l = k_l * e_l
    u_a = k_alpha * e_a
    cb, sb = xp.cos(beta), xp.sin(beta)
    ca, sa = xp.cos(alpha), xp.sin(alpha)
    f11, f12 = -cb, l * sb
    f21, f22 = -sb / d, -l * cb / d
    q = sa / xp.maximum(l, l_min)
    a = xp.stack([f11 * u_l + f12 * u_a, f21 * u_l + f22 * u_a], axis=-1)
    # M = -F^{-1} D,  D = [[cos a, 0], [-sin a / l, -1]]
    m = xp.stack([xp.stack([-(f11 * ca - f12 * q), f12], axis=-1),
                  xp.stack([-(f21 * ca - f22 * q), f22], axis=-1)], axis=-2)
    return a, m, xp.stack([l, alpha], axis=-1), xp.stack([e_l, e_a], axis=-1)


def leader_follower_law(pose, pose_l, cmd_l, l_ref, alpha_ref, d, k_l, k_alpha,
                        l_min=1e-3, xp=np):
    """(v, omega) of followers ``pose`` (N, 3) behind leaders ``pose_l`` (N, 3)
    moving with commands ``cmd_l`` (N, 2): eq. (4)-(5) (see module doc)."""
    a, m, _, _ = leader_follower_terms(pose, pose_l, l_ref, alpha_ref, d, k_l,
                                       k_alpha, l_min, xp)
    return a + xp.sum(m * cmd_l[:, None, :], axis=-1)


def tree_levels(leader, block="LeaderFollower"):
    """Depth of each agent in the leader forest; rejects bad indices and cycles.

    Returns ``depth`` (N,) int (0 for agents with ``leader = -1``).
    """
    leader = np.asarray(leader)
    n = leader.shape[0]
    if np.any(leader < -1) or np.any(leader >= n):
        raise ParameterError("leader indices must be -1 or in [0, N)", block=block,
                             param="leader", found=leader[(leader < -1) | (leader >= n)])
    if np.any(leader == np.arange(n)):
        raise ParameterError("an agent cannot follow itself", block=block,
                             param="leader",
                             found=np.flatnonzero(leader == np.arange(n)))
    depth = np.where(leader < 0, 0, -1)
    for level in range(1, n + 1):           # at most N levels; vectorized per level
        todo = depth < 0
        if not np.any(todo):
            break
        ready = todo & (depth[np.maximum(leader, 0)] == level - 1) & (leader >= 0)
        if not np.any(ready):
            break
        depth = np.where(ready, level, depth)
    if np.any(depth < 0):
        raise ParameterError("the leader graph has a cycle: every chain of "
                             "leaders must end at an agent with leader -1",
                             block=block, param="leader",
                             found=np.flatnonzero(depth < 0))
    return depth


class LeaderFollower(Block):
    r"""Leader-follower formations (chains and trees) of N unicycles in one block.

    Each follower ``i`` (``leader[i] >= 0``) keeps its off-axis point at
    distance ``l_ref[i]`` and tracking angle ``alpha_ref[i]`` from agent
    ``leader[i]`` by eqs. (2)-(5) of the AVLib paper (module docstring; note
    the corrected sign). Agents with ``leader[i] = -1`` (formation leaders,
    free agents) pass their command through from ``cmd_in``.

    How leader velocities arrive: ``cmd_in`` holds commands for *all* N
    agents; only the roots' rows are used (e.g. wire a PointToPoint over all N
    agents, or a Constant: the followers' rows are ignored). Inside one
    ``output()`` call the block computes followers level by level of the
    leader tree (a static loop over tree depths, vectorized within a depth),
    each level using the commands just computed for its leaders. So one block
    handles chains and trees of any depth, and there is no algebraic loop.

    Ports
    -----
    pose : in, (N, 3) — poses of all agents of the group.
    cmd_in : in, (N, 2) — (v, omega) of the roots (followers' rows ignored).
    cmd : out, (N, 2) — (v, omega) of every agent.
    error : out, (N, 2) — ``(l_ref - l, wrap(alpha_ref - alpha))``; 0 for roots.
    ref : in, (N, 2), only with ``references_input=True`` — ``(l_ref,
        alpha_ref)`` per agent (roots' rows ignored), direct feedthrough; it
        replaces the fixed ``l_ref``/``alpha_ref`` (formation switching: wire
        a :class:`Supervisor` output table of reference arrays here).

    Parameters
    ----------
    leader : (N,) int — agent followed by agent i, -1 for roots.
    l_ref, alpha_ref : float or (N,) — desired distance (m) and angle (rad);
        ignored with ``references_input=True`` (default 0 there).
    references_input : bool — read the references from the ``ref`` port.
    d : float > 0 — off-axis distance (m).
    k_l, k_alpha : float or (N,) > 0 — gains (1/s).
    l_min : float > 0 — lower clamp of ``l`` in the ``sin(alpha)/l`` term.

    Numeric parameters
    ------------------

    ``d``, ``l_ref``, ``alpha_ref``, ``k_l``, ``k_alpha`` (all (N,) but
    ``d``) and ``l_min`` are numeric parameters (``"follow.k_alpha"``); the
    leader tree and ``references_input`` are structural.

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> lf = av.controllers.LeaderFollower([-1, 0, 1], l_ref=1.0, alpha_ref=0.0)
    >>> pose = np.array([[0.0, 0, 0], [-1.1, 0, 0], [-2.2, 0, 0]])
    >>> cmd = lf.output(0, {}, {"pose": pose, "cmd_in": np.ones((3, 2)) * [1, 0]}, np)["cmd"]
    >>> np.round(cmd[:, 0], 6)
    array([1., 1., 1.])
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {'leader': {'formation_references': {'n': '$agents',
                                                   'spacing': 1.5,
                                                   'd': 0.2,
                                                   'tree': 'star',
                                                   'state': 'leader'}},
               'd': 0.2,
               'references_input': True}

    def __init__(self, leader, l_ref=None, alpha_ref=None, *, d=0.1, k_l=1.0,
                 k_alpha=1.0, l_min=1e-3, references_input=False):
        super().__init__()
        name = "LeaderFollower"
        try:
            lead = np.asarray(leader)
            ok = lead.ndim == 1 and lead.size > 0 and np.all(lead == np.round(lead))
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ParameterError("leader must be a 1-D integer array (-1: root)",
                                 block=name, param="leader", found=repr(leader)[:80])
        self.leader = lead.astype(np.int64)
        self.n = n = self.leader.shape[0]
        self.depth = tree_levels(self.leader, name)
        self.references_input = bool(references_input)
        if not self.references_input and (l_ref is None or alpha_ref is None):
            raise ParameterError("l_ref and alpha_ref are needed (or "
                                 "references_input=True and a 'ref' input)",
                                 block=name, param="l_ref" if l_ref is None
                                 else "alpha_ref", found=None)
        dp = self.declare_parameter
        dp("d", positive_scalar(d, name, "d"), bounds=(1e-9, None), unit="m")
        dp("l_ref", agent_array(0.0 if l_ref is None else l_ref, n, name, "l_ref",
                                nonnegative=True), bounds=(0, None), unit="m")
        dp("alpha_ref", agent_array(0.0 if alpha_ref is None else alpha_ref, n, name,
                                    "alpha_ref"), unit="rad")
        dp("k_l", agent_array(k_l, n, name, "k_l", positive=True), bounds=(1e-12, None),
           unit="1/s")
        dp("k_alpha", agent_array(k_alpha, n, name, "k_alpha", positive=True),
           bounds=(1e-12, None), unit="1/s")
        dp("l_min", positive_scalar(l_min, name, "l_min"), bounds=(1e-12, None), unit="m")
        self.levels = [np.flatnonzero(self.depth == k)
                       for k in range(int(self.depth.max()) + 1)]
        self.lead_pos = [None]
        for k in range(1, len(self.levels)):
            prev = np.full(n, -1, dtype=np.int64)
            prev[self.levels[k - 1]] = np.arange(len(self.levels[k - 1]))
            self.lead_pos.append(prev[self.leader[self.levels[k]]])
        order = np.concatenate(self.levels)
        self._inv = np.argsort(order)
        self._is_f = self.leader >= 0
        self._safe_leader = np.maximum(self.leader, 0)
        self.declare_input("pose", (n, 3), unit="m, m, rad")
        self.declare_input("cmd_in", (n, 2), unit="m/s, rad/s", labels=("v", "omega"),
                           doc="roots' commands; followers' rows ignored")
        if self.references_input:
            self.declare_input("ref", (n, 2), unit="m, rad", labels=("l_ref", "alpha_ref"),
                               doc="references (l_ref, alpha_ref); roots' rows ignored")
        self.declare_output("cmd", (n, 2), unit="m/s, rad/s", labels=("v", "omega"))
        self.declare_output("error", (n, 2), unit="m, rad", labels=("l", "alpha"))

    def output(self, t, x, u, xp):
        pose, cmd_in = u["pose"], u["cmd_in"]
        if self.references_input:
            l_ref, alpha_ref = u["ref"][:, 0], u["ref"][:, 1]
        else:
            l_ref, alpha_ref = self.l_ref, self.alpha_ref
        a, m, _, err = leader_follower_terms(
            pose, pose[self._safe_leader], l_ref, alpha_ref, self.d,
            self.k_l, self.k_alpha, self.l_min, xp)
        pieces = [cmd_in[self.levels[0]]]
        for k in range(1, len(self.levels)):
            idx = self.levels[k]
            c0 = pieces[k - 1][self.lead_pos[k]]
            pieces.append(a[idx] + xp.sum(m[idx] * c0[:, None, :], axis=-1))
        cmd = xp.concatenate(pieces, axis=0)[self._inv] if len(pieces) > 1 else cmd_in
        err = xp.where(self._is_f[:, None], err, 0.0)
        return {"cmd": cmd, "error": err}
