"""Reference solution of lab 2 (kept with the tests, not in the template).

Lab 2: go to a goal by feedback linearisation. Write GoToGoal.output,
then run `avblocks lab check 2 lab2_go_to_goal.py`.

A unicycle cannot move sideways, but the point p at distance d ahead of it,

    p = (x + d cos(theta), y + d sin(theta)),

can move in any direction: its velocity is

    dp/dt = [[cos(theta), -d sin(theta)],
             [sin(theta),  d cos(theta)]] [v, omega]^T,

a matrix that is invertible for d != 0. Choose the velocity you want the
point to have, w = K (goal - p), saturated so that |w| <= v_max (scale w
down to length v_max when it is longer), and invert:

    v     =  cos(theta) w_x + sin(theta) w_y
    omega = (-sin(theta) w_x + cos(theta) w_y) / d

Then p obeys dp/dt = K (goal - p): it reaches the goal exponentially, with
rate K (AVLib paper, Sec. III.B).

Rules of the library: the agent axis comes first, compute with `xp`, never
loop over agents, never write into `u`.
"""

import numpy as np

import avblocks as av


class GoToGoal(av.Block):
    """Drive N unicycles' look-ahead points to their goals.

    Ports: pose (N, 3) in; cmd (N, 2) out = (v, omega).
    Parameters: goal (N, 2); d (look-ahead distance, m); gain K (1/s);
    v_max (largest speed of the look-ahead point, m/s).
    """

    def __init__(self, goal, d=0.1, gain=1.0, v_max=1.0):
        super().__init__()
        self.goal = np.asarray(goal, dtype=float)
        self.n = len(self.goal)
        self.d, self.gain, self.v_max = float(d), float(gain), float(v_max)
        self.declare_input("pose", (self.n, 3), unit="m, m, rad")
        self.declare_output("cmd", (self.n, 2), unit="m/s, rad/s")

    def output(self, t, x, u, xp):
        pose = u["pose"]
        c, s = xp.cos(pose[:, 2]), xp.sin(pose[:, 2])
        ex = self.goal[:, 0] - pose[:, 0] - self.d * c
        ey = self.goal[:, 1] - pose[:, 1] - self.d * s
        norm = xp.sqrt(ex * ex + ey * ey)
        k = xp.minimum(self.gain, self.v_max / xp.maximum(norm, 1e-300))
        wx, wy = k * ex, k * ey
        return {"cmd": xp.stack([c * wx + s * wy, (s * wx - c * wy) / self.d], axis=-1)}
