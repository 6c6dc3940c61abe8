"""Raising its own limits before a memory bomb.

While loading, sets the soft limit of every resource limit the grader set
(address space, open files, file size, core size, CPU time, processes) to
its hard limit, which a process may always do, then ``wheels_to_cmd``
reserves 6 GiB of address space (never touched, so no memory is used
whatever happens). The grader sets each hard limit to the soft one (and
a student's process run as root holds no capability to raise a hard
limit), so the reservation fails as a MemoryError.

expect: your code raised MemoryError
expect: (the grader allows 4096 MiB: --memory)
"""

import resource

import numpy as np

import avblocks as av

for _name in ("RLIMIT_AS", "RLIMIT_NOFILE", "RLIMIT_FSIZE", "RLIMIT_CORE", "RLIMIT_CPU",
              "RLIMIT_NPROC"):
    _rl = getattr(resource, _name, None)
    if _rl is None:
        continue
    for _want in (resource.RLIM_INFINITY, resource.getrlimit(_rl)[1]):
        try:
            resource.setrlimit(_rl, (_want, _want))
            break
        except (ValueError, OSError):
            pass


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
    big = np.empty(6 * 2 ** 30, dtype=np.uint8)
    raise LookupError(f"reserved {big.nbytes} bytes beyond the grader's limit")
