"""Lab 1: vehicle kinematics. Write the unicycle model and the differential
drive's wheel map, then run `avblocks lab check 1 lab1_kinematics.py`.

The unicycle (AVLib paper, eq. 1), for every agent n:

    dx/dt     = v cos(theta)
    dy/dt     = v sin(theta)
    dtheta/dt = omega

A differential-drive robot with wheel radius r and track (distance between
the wheels) L, turning its wheels at omega_left and omega_right [rad/s],
moves as a unicycle with

    v     = r (omega_right + omega_left) / 2
    omega = r (omega_right - omega_left) / L

Rules of the library (docs/writing-blocks.md): the agent axis comes first,
compute with `xp` (the array namespace you are handed, not `np`), never
loop over agents, never write into `x` or `u`.
"""

import numpy as np

import avblocks as av


class MyUnicycle(av.Block):
    """N unicycles. Ports: cmd (N, 2) in = (v, omega); pose (N, 3) out =
    (x, y, theta). Continuous state: pose (N, 3)."""

    def __init__(self, pose0):
        super().__init__()
        pose0 = np.asarray(pose0, dtype=float)
        self.n = len(pose0)
        self.declare_input("cmd", (self.n, 2), unit="m/s, rad/s", feedthrough=False)
        self.declare_continuous_state("pose", pose0)
        self.declare_output("pose", (self.n, 3), unit="m, m, rad")

    def output(self, t, x, u, xp):
        return {"pose": x["pose"]}

    def derivative(self, t, x, u, xp):
        pose, cmd = x["pose"], u["cmd"]
        # TODO: return {"pose": rates}, rates an (N, 3) array of
        # (dx/dt, dy/dt, dtheta/dt) from eq. 1. Hint: xp.stack([...], axis=-1)
        raise NotImplementedError("write MyUnicycle.derivative (eq. 1)")


def wheels_to_cmd(wheels, radius, track):
    """(N, 2) wheel speeds (omega_left, omega_right) [rad/s] -> (N, 2)
    unicycle commands (v, omega), for wheel radius ``radius`` and distance
    between the wheels ``track`` [m]."""
    # TODO
    raise NotImplementedError("write wheels_to_cmd")
