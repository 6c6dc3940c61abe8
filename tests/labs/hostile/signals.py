"""Signals to the grader, its supervisor and the process group.

While loading: SIGSTOP and SIGKILL to its parent (the supervisor) and to
the grader (the supervisor's parent, found in /proc), SIGKILL to the
grader's process group; then, in ``wheels_to_cmd``, SIGKILL to its own
process group. With Landlock (ABI 6+) every signal to a process outside
the student's own is refused; the last one ends the student's process
only, which the grader reports.

expect: not written yet: NotImplementedError: write MyUnicycle.derivative
expect: the process running your code ended (signal 9 (SIGKILL)) in check
expect: in check 'differential drive: wheels_to_cmd' of lab 1
"""

import os
import signal

import numpy as np

import avblocks as av

REFUSED = []


def _send(pid, sig, group=False):
    try:
        (os.killpg if group else os.kill)(pid, sig)
    except OSError as e:
        REFUSED.append((pid, sig, e.errno))


_sup = os.getppid()
try:
    with open(f"/proc/{_sup}/stat") as f:
        _grader = int(f.read().rsplit(")", 1)[1].split()[1])
except (OSError, ValueError, IndexError):
    _grader = None
for _pid in (_sup, _grader):
    if _pid and _pid > 1:
        _send(_pid, signal.SIGSTOP)
        _send(_pid, signal.SIGKILL)
        try:
            _send(os.getpgid(_pid), signal.SIGKILL, group=True)
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
    os.killpg(0, signal.SIGKILL)
