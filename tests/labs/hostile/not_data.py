"""Objects that are not data.

``wheels_to_cmd`` returns a function; ``derivative`` returns a dict whose
port is a generator; both are sent as the name of what they are, never as
objects, and fail the check that asked.

expect: returned a function object, not numbers
expect: a generator object
"""

import numpy as np

import avblocks as av


class MyUnicycle(av.Block):
    def __init__(self, pose0):
        super().__init__()
        pose0 = np.asarray(pose0, dtype=float)
        self.n = len(pose0)
        self.declare_input("cmd", (self.n, 2), feedthrough=False)
        self.declare_continuous_state("pose", pose0)
        self.declare_output("pose", (self.n, 3))

    def output(self, t, x, u, xp):
        return {"pose": x["pose"]}

    def derivative(self, t, x, u, xp):
        return {"pose": (i for i in range(3))}


def wheels_to_cmd(wheels, radius, track):
    return wheels_to_cmd
