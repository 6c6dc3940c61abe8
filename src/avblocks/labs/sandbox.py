"""The grader's side of the process that runs a student's code.

:class:`Sandbox` starts the child (:mod:`avblocks.labs._child`) in a
session of its own, under a supervisor where the platform has one
(:func:`oscalls.supervise`), with its own empty temporary folder as the
current folder and home, an environment that holds nothing of the
grader's, and the limits of :class:`SandboxLimits`. It then talks to it
only through the data-only channel (:mod:`avblocks.labs.wire`):
:meth:`Sandbox.request` sends one request and waits, until a deadline,
for the answer to *that* request.

What can go wrong on the child's side is one of four exceptions, each a
clean failure of the submission (never of the grader):

* :class:`StudentRaised`: the student's code raised; its record says what
  and where;
* :class:`TimedOut`: no answer before the deadline (the child is killed);
* :class:`Died`: the child ended (``os._exit``, a crash, a signal, a CPU
  limit), with its status;
* :class:`ChannelBroken`: something arrived that is not the answer to the
  request (garbage, a forged or oversized message, too much in total).

:meth:`Sandbox.close` kills the child with everything it started
(grandchildren, daemons: see :func:`oscalls.kill_tree`) and removes its
folder, on every path out.
"""

from __future__ import annotations

import contextlib
import os
import queue
import re
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from . import oscalls, wire

#: how the child starts: the folder holding avblocks comes first on its path
_BOOT = ("import sys; sys.path.insert(0, sys.argv[1]); "
         "from avblocks.labs._child import main; main()")
_SRC = str(Path(__file__).resolve().parents[2])


@dataclass(frozen=True)
class SandboxLimits:
    """The limits of one student's process.

    Attributes
    ----------
    memory_mb : int
        Address space (``RLIMIT_AS``) in MiB; 0: none.
    cpu_s : float
        CPU time of the whole process (``RLIMIT_CPU``), a backstop behind the
        wall-clock limits of each check.
    processes : int
        Processes and threads it may add (``RLIMIT_NPROC``, Linux, not root).
    files : int
        Open files (``RLIMIT_NOFILE``).
    file_mb : int
        Largest file it may write (``RLIMIT_FSIZE``), in MiB.
    submission_bytes : int
        Everything it may send the grader, all messages together.
    wire : wire.Limits
        The limits of one message.
    """

    memory_mb: int = 4096
    cpu_s: float = 600.0
    processes: int = 64
    files: int = 256
    file_mb: int = 64
    submission_bytes: int = 1 << 30
    wire: wire.Limits = wire.DEFAULT


class SandboxError(Exception):
    """The submission's process failed to answer (base class)."""


class StudentRaised(SandboxError):
    """The student's code raised; ``record`` is the child's error record
    (plain data, checked by :func:`clean_record`)."""

    def __init__(self, record):
        super().__init__(record.get("kind", "?"))
        self.record = record


class TimedOut(SandboxError):
    """No answer before the deadline."""


class Died(SandboxError):
    """The child ended; ``status`` says how (``exit status 7``, ``signal 9 (SIGKILL)``)."""

    def __init__(self, status, returncode=None):
        super().__init__(status)
        self.status = status
        self.returncode = returncode


class ChannelBroken(SandboxError):
    """Something arrived that is not the answer to the request."""


def clean_record(rec) -> dict:
    """A child's error record reduced to known fields of known types (it is
    the student's process's data: never trusted further than that)."""
    if not isinstance(rec, dict):
        return {"kind": "?", "message": "", "flags": []}
    out = {"kind": _text(rec.get("kind"), 60) or "?",
           "message": _text(rec.get("message"), 1000),
           "flags": [f for f in rec.get("flags", []) if isinstance(f, str)][:10]
           if isinstance(rec.get("flags"), list) else []}
    for key in ("line",):
        v = rec.get(key)
        if type(v) is int and 0 < v < 10 ** 7:
            out[key] = v
    for key in ("func", "readonly"):
        v = _text(rec.get(key), 120)
        if v:
            out[key] = v
    r = rec.get("returns")
    if isinstance(r, list):
        out["returns"] = [x for x in r if type(x) is int and 0 < x < 10 ** 7][:5]
    if isinstance(rec.get("cause"), dict) and "cause" not in rec.get("cause", {}):
        out["cause"] = clean_record(rec["cause"])
    return out


_ANSI = re.compile(r"\x1b\[[0-?]*[ -/]*[@-~]|\x1b[@-_]")


def _text(v, n) -> str:
    """``v`` as one line of printable text of at most ``n`` characters
    (terminal escape sequences removed, other control characters spaces)."""
    if not isinstance(v, str):
        return ""
    v = "".join(c if c.isprintable() else " " for c in _ANSI.sub("", v))
    v = " ".join(v.split())
    return v if len(v) <= n else v[:n - 3] + "..."


class Sandbox:
    """One student's process, started by :meth:`start`.

    Parameters
    ----------
    limits : SandboxLimits
    """

    def __init__(self, limits=SandboxLimits()):
        self.limits = limits
        self.workdir = None
        self.run = None
        self.ready = None
        self._q: queue.Queue = queue.Queue()
        self._seq = 0
        self._received = 0
        self._closed = False
        self._status = None
        self._broken = None
        self.reader = None

    # ------------------------------------------------------------ start and stop
    def start(self):
        """Start the child (returns at once; :meth:`wait_ready` waits for it)."""
        self.workdir = tempfile.mkdtemp(prefix="avblocks-lab-")
        self.run = oscalls.Supervised(
            [sys.executable, "-I", "-B", "-c", _BOOT, _SRC], cleanup=self.workdir,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
            env=oscalls.child_environment(self.workdir), cwd=self.workdir)
        proc = self.run.proc
        self._out = proc.stdout.fileno()
        self._in = proc.stdin.fileno()
        if oscalls.IS_WINDOWS or not oscalls.enabled("select"):
            # no select() on pipes: a reader thread hands frames over a queue
            self.reader = threading.Thread(target=self._read_loop, daemon=True,
                                           name="avblocks-lab-reader")
            self.reader.start()
        lim = self.limits
        config = {"workdir": self.workdir, "off": oscalls.off(), "grader": os.getpid(),
                  "wire": {k: getattr(lim.wire, k) for k in lim.wire.__dataclass_fields__},
                  "limits": {"memory_mb": lim.memory_mb, "cpu_s": lim.cpu_s,
                             "processes": lim.processes, "files": lim.files,
                             "file_mb": lim.file_mb}}
        with contextlib.suppress(OSError, TimeoutError):
            oscalls.write_all(self._in, wire.encode(config), time.monotonic() + 30)
        return self

    @property
    def supervised(self) -> bool:
        return self.run is not None and self.run.supervised

    def wait_ready(self, deadline) -> dict:
        """Wait for the child's ``ready`` (until ``deadline``, a monotonic
        time); ``{limit: what was set}``."""
        msg = self._next(deadline, what="to start")
        if not (isinstance(msg, dict) and isinstance(msg.get("ready"), dict)):
            raise ChannelBroken("the process did not start as the grader's child")
        self.ready = {str(k)[:40]: _text(v, 200) for k, v in msg["ready"].items()}
        return self.ready

    def close(self) -> int | None:
        """Kill the child with everything it started, remove its folder;
        the child's return code when it had ended by itself."""
        if self._closed:
            return self._status
        self._closed = True
        try:
            if self.run is not None:
                # kill first: a child that saw its input close would exit by
                # itself and orphan what it started before the kill could see it
                self._status = self.run.kill()
                proc = self.run.proc
                for f in (proc.stdin, proc.stdout):
                    with contextlib.suppress(OSError):
                        f.close()
        finally:
            if self.workdir:
                oscalls.remove_tree(self.workdir)
        return self._status

    def ended(self, wait=5.0) -> Died:
        """After the channel ended: the child's status, as a :class:`Died`."""
        code = self.run.exit_code(wait) if self.run is not None else None
        return Died(oscalls.status_text(code), code)

    # ------------------------------------------------------------ the channel
    def _read_loop(self):
        fd = self._out
        limits = self.limits.wire
        budget = self.limits.submission_bytes

        def read_exact(n):
            buf = bytearray()
            while len(buf) < n:
                chunk = os.read(fd, min(n - len(buf), 1 << 20))
                if not chunk:
                    raise EOFError
                buf += chunk
            return bytes(buf)

        try:
            while True:
                value, n = wire.read(read_exact, limits)
                self._received += n
                if self._received > budget:
                    self._q.put(("broken", f"it sent more than {budget} bytes in all "
                                           f"(the grader's limit per submission)"))
                    return
                self._q.put(("msg", value))
        except EOFError:
            self._q.put(("eof", None))
        except wire.WireError as e:
            self._q.put(("broken", f"it sent {e}"))
        except (OSError, ValueError) as e:
            self._q.put(("eof", str(e)))
        except MemoryError:
            self._q.put(("broken", "it sent more than the grader could hold"))

    def _next(self, deadline, what="to answer"):
        if self.reader is None:
            return self._next_direct(deadline, what)
        left = deadline - time.monotonic()
        try:
            kind, value = self._q.get(timeout=max(0.0, left)) if left > 0 else \
                self._q.get_nowait()
        except queue.Empty:
            raise TimedOut(what) from None
        if kind == "msg":
            return value
        self._q.put((kind, value))          # stays broken for later requests
        if kind == "eof":
            raise self.ended()
        raise ChannelBroken(value)

    def _next_direct(self, deadline, what):
        """The next frame, read here with ``select`` (POSIX)."""
        if self._broken is not None:
            raise self._broken
        fd = self._out

        def read_exact(n):
            try:
                return oscalls.read_exact(fd, n, deadline)
            except TimeoutError:
                raise TimedOut(what) from None

        try:
            value, n = wire.read(read_exact, self.limits.wire)
        except EOFError:
            self._broken = self.ended()
            raise self._broken from None
        except OSError:
            self._broken = self.ended()
            raise self._broken from None
        except wire.WireError as e:
            self._broken = ChannelBroken(f"it sent {e}")
            raise self._broken from None
        except MemoryError:
            self._broken = ChannelBroken("it sent more than the grader could hold")
            raise self._broken from None
        self._received += n
        if self._received > self.limits.submission_bytes:
            self._broken = ChannelBroken(f"it sent more than {self.limits.submission_bytes} "
                                         f"bytes in all (the grader's limit per submission)")
            raise self._broken
        return value

    def request(self, op, deadline, **fields):
        """Send ``{"op": op, **fields}`` and return the answer's value
        (raises :class:`StudentRaised`, :class:`TimedOut`, :class:`Died`,
        :class:`ChannelBroken`)."""
        self._seq += 1
        seq = self._seq
        msg = {"id": seq, "op": op, **fields}
        try:
            data = wire.encode(msg, self.limits.wire, allow_xp=True)
        except wire.WireError as e:          # the grader's own request: a check's bug
            raise ValueError(f"a request the channel cannot carry: {e}") from None
        try:
            oscalls.write_all(self._in, data, deadline)
        except TimeoutError:
            raise TimedOut("to read its input") from None
        except OSError:
            raise self.ended() from None
        reply = self._next(deadline)
        if not (isinstance(reply, dict) and reply.get("id") == seq
                and (("ok" in reply) != ("error" in reply))):
            raise ChannelBroken("it sent an answer to a request the grader did not make "
                                "(something wrote into the channel)")
        if "error" in reply:
            raise StudentRaised(clean_record(reply["error"]))
        return reply["ok"]
