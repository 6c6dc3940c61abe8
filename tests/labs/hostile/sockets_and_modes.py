"""Sockets, and changing files' modes and times.

Landlock stops TCP and writes, but not UDP, Unix sockets (a Docker or
ssh-agent socket, an abstract one), ``chmod``, ``chown`` or ``utime``.
While loading, it tries each: a UDP datagram to 127.0.0.1, a Unix socket
(abstract and named), ``chmod``/``utime`` of a module of the installed
avblocks package (a changed mode used to stop a whole class's run) and of
its own folder. ``wheels_to_cmd`` raises with what got through. On Linux
(x86-64, arm64) the student's process has no socket and no call that
changes a file's mode, owner or times (seccomp).

expect: your code raised LookupError: nothing got through
"""

import os
import socket
from pathlib import Path

import numpy as np

import avblocks as av

THROUGH = []


def _try(what, fn):
    try:
        fn()
        THROUGH.append(what)
    except OSError:
        pass


def _udp():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(b"avblocks-hostile-TOKEN", ("127.0.0.1", 9))


def _abstract():
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.bind("\0avblocks-hostile-TOKEN")


def _module():
    return Path(av.__file__).resolve().parent / "labs" / "registry.py"


_try("udp", _udp)
_try("abstract unix socket", _abstract)
_try("chmod of the grader's module", lambda: os.chmod(_module(), 0o600))
_try("utime of the grader's module", lambda: os.utime(_module(), (0, 0)))
_try("chmod of its folder", lambda: os.chmod(os.getcwd(), 0o700))


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
    raise LookupError(f"got through: {', '.join(THROUGH)}" if THROUGH else
                      "nothing got through")
