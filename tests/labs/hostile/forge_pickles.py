"""Forged results over the channel, as pickles.

The old grader read pickled ``CheckResult`` objects from a pipe; this file
(the untouched template otherwise) writes "passed" results and an object
whose ``__reduce__`` would run code in whoever unpickles it into every
pipe it can write to. The new channel carries no pickle: the first byte
that is not a frame breaks the channel, and the submission fails.

expect: broke the grader's channel while loading the file
expect: does not start with b'AVL1'
"""

import os
import pickle
import stat

import numpy as np

import avblocks as av


class _Evil:
    def __reduce__(self):
        return (os.system, ("echo pwned > /tmp/avblocks-hostile-TOKEN-pickle",))


_payload = pickle.dumps(("result", {"name": "ports", "passed": True, "message": "ok"})) + \
    pickle.dumps(_Evil()) + pickle.dumps(("done", None))
for fd in range(3, 64):
    try:
        if stat.S_ISFIFO(os.fstat(fd).st_mode):
            os.write(fd, _payload)
    except OSError:
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
    raise NotImplementedError("write wheels_to_cmd")
