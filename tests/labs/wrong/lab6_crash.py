"""Reference solution of lab 6 (kept with the tests, not in the template).

Lab 6: from simulation to robots. Write GroupHold.output, then run
`avblocks lab check 6 lab6_robots.py` (it needs the ros2 extra:
pip install 'avblocks[ros2]').

On robots, the vehicle model block is replaced by
avblocks.interfaces.ros2.Robots: the same ports (cmd in, pose out) plus
`fresh` (N,) bool, false for a robot whose pose has not arrived within the
watchdog's timeout. The Robots block already stops a silent robot. Your
controller goes one step further: a group that moves together (a
formation, a convoy) must hold *every* robot still while *any* of them is
silent, and go on by itself when they all report again.

    cmd_i = go-to-goal law_i   if every robot is fresh
    cmd_i = (0, 0)             otherwise

The go-to-goal law (lab 2) is given: av.controllers.point_to_point_law.
Compute with `xp`; no Python `if` on array values (use xp.where or
multiply by a 0/1 array); never write into the inputs.
"""

import numpy as np

import avblocks as av


class GroupHold(av.Block):
    """Go to goals, all together or not at all.

    Ports: pose (N, 3) in; fresh (N,) bool in; cmd (N, 2) out.
    Parameters: goal (N, 2); d, gain, v_max of the go-to-goal law.
    """

    def __init__(self, goal, d=0.2, gain=1.0, v_max=0.2):
        super().__init__()
        self.goal = np.asarray(goal, dtype=float)
        self.n = len(self.goal)
        self.d, self.gain, self.v_max = float(d), float(gain), float(v_max)
        self.declare_input("pose", (self.n, 3), unit="m, m, rad")
        self.declare_input("fresh", (self.n,), dtype="bool")
        self.declare_output("cmd", (self.n, 2), unit="m/s, rad/s")

    def output(self, t, x, u, xp):
        law = av.controllers.point_to_point_law(u["pose"], xp.asarray(self.goal), self.d,
                                                self.gain, self.v_max, xp)
        everyone = xp.all(u["fresh"])
        if not everyone:
            raise RuntimeError("a robot is silent")
        return {"cmd": xp.where(everyone, law, 0.0 * law)}
