"""A memory bomb.

``wheels_to_cmd`` asks for 80 GB. The student's process may use 4096 MiB
of address space (``RLIMIT_AS``): the allocation fails at once as a
MemoryError in the student's code, and the grader says so.

expect: your code raised MemoryError
expect: (the grader allows 4096 MiB: --memory)
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
        raise NotImplementedError("write MyUnicycle.derivative (eq. 1)")


def wheels_to_cmd(wheels, radius, track):
    return np.ones(10 ** 10)
