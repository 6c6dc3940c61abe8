"""Reference solution of lab 3 (kept with the tests, not in the template).

Lab 3: leader-following formations (AVLib paper, eqs. 2-5). Write
`follower_cmd`, then run `avblocks lab check 3 lab3_formation.py`.

A follower n (pose x_n, y_n, theta_n) keeps its off-axis point
(x_n^d, y_n^d) = (x_n + d cos theta_n, y_n + d sin theta_n) at distance
l_ref and tracking angle alpha_ref from its leader 0 (pose x_0, y_0,
theta_0, commanded velocities v_0, omega_0):

    zeta  = atan2(y_0 - y_n^d, x_0 - x_n^d)
    l     = sqrt((x_0 - x_n^d)^2 + (y_0 - y_n^d)^2)            (2)
    alpha = wrap(zeta - theta_0),   beta = wrap(zeta - theta_n)

    u_l     = K_l (l_ref - l)
    u_alpha = K_alpha wrap(alpha_ref - alpha)

    [v_n, omega_n]^T = F^-1 ( [u_l, u_alpha]^T - D [v_0, omega_0]^T )   (4)

    F^-1 = [[ -cos(beta),        l sin(beta)      ],
            [ -sin(beta) / d,   -l cos(beta) / d  ]]                  (5)

    D    = [[  cos(alpha),       0 ],
            [ -sin(alpha) / l,  -1 ]]

(The paper prints +1 in D's lower right corner; differentiating (2) gives
-1, which this lab uses: see avblocks.controllers.leader_follower.)
Then dl/dt = u_l and dalpha/dt = u_alpha: both errors decay as exp(-K t).
wrap(a) = (a + pi) mod 2 pi - pi, av.utility.wrap_angle(a, xp).

Rules of the library: the agent axis comes first, compute with `xp`, never
loop over agents, never write into the inputs.
"""

import numpy as np

import avblocks as av


def follower_cmd(pose, pose_l, cmd_l, l_ref, alpha_ref, d, k_l, k_alpha, xp=np):
    """(N, 2) commands (v, omega) of N followers.

    pose (N, 3) followers; pose_l (N, 3) and cmd_l (N, 2) their leaders' poses
    and commanded (v_0, omega_0); l_ref, alpha_ref, k_l, k_alpha scalars or
    (N,); d > 0 the off-axis distance.
    """
    wrap = av.utility.wrap_angle
    c, s = xp.cos(pose[:, 2]), xp.sin(pose[:, 2])
    dx = pose_l[:, 0] - (pose[:, 0] + d * c)
    dy = pose_l[:, 1] - (pose[:, 1] + d * s)
    l = xp.sqrt(dx * dx + dy * dy)
    zeta = xp.arctan2(dy, dx)
    assert xp.all(l > 1.0), "followers too close"
    alpha = wrap(zeta - pose_l[:, 2], xp)
    beta = wrap(zeta - pose[:, 2], xp)
    u_l = k_l * (l_ref - l)
    u_a = k_alpha * wrap(alpha_ref - alpha, xp)
    v0, w0 = cmd_l[:, 0], cmd_l[:, 1]
    r1 = u_l - xp.cos(alpha) * v0                   # [u_l, u_a] - D [v0, w0]
    r2 = u_a + xp.sin(alpha) / l * v0 + w0
    v = -xp.cos(beta) * r1 + l * xp.sin(beta) * r2
    w = -xp.sin(beta) / d * r1 - l * xp.cos(beta) / d * r2
    return xp.stack([v, w], axis=-1)


class MyFormation(av.Block):
    """Agent 0 leads, agents 1..N-1 follow it (already written: it calls
    follower_cmd). Ports: pose (N, 3) in; cmd_in (N, 2) in (row 0: the
    leader's command); cmd (N, 2) out."""

    def __init__(self, n, l_ref, alpha_ref, d=0.1, k_l=1.0, k_alpha=1.0):
        super().__init__()
        self.n = n
        self.l_ref = np.broadcast_to(np.asarray(l_ref, dtype=float), (n - 1,)).copy()
        self.alpha_ref = np.broadcast_to(np.asarray(alpha_ref, dtype=float), (n - 1,)).copy()
        self.d, self.k_l, self.k_alpha = float(d), float(k_l), float(k_alpha)
        self.declare_input("pose", (n, 3), unit="m, m, rad")
        self.declare_input("cmd_in", (n, 2), unit="m/s, rad/s")
        self.declare_output("cmd", (n, 2), unit="m/s, rad/s")

    def output(self, t, x, u, xp):
        pose, cmd_in = u["pose"], u["cmd_in"]
        lead = xp.broadcast_to(pose[:1], (self.n - 1, 3))
        lead_cmd = xp.broadcast_to(cmd_in[:1], (self.n - 1, 2))
        follow = follower_cmd(pose[1:], lead, lead_cmd, self.l_ref, self.alpha_ref, self.d,
                              self.k_l, self.k_alpha, xp)
        return {"cmd": xp.concatenate([cmd_in[:1], follow], axis=0)}
