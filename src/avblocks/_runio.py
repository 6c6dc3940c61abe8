"""What keeps an ``avblocks run`` from losing data: signals, the output folder,
atomic files.

* :class:`SignalGuard` turns the first SIGINT, SIGTERM or SIGHUP into an
  :class:`Interrupted` (a ``KeyboardInterrupt``), which :func:`simulate`
  catches to return what it logged so far; every later signal is only
  noted while the results are written, so a second Ctrl-C never loses them.
  The exit status is then ``128 + signal number`` (130, 143, 129).
* :func:`prepare_output` makes the output folder and proves it writable
  before anything is simulated.
* :func:`atomic_path` gives a temporary name next to the target, renamed
  into place only when the writer finished: a full disk or an interrupt
  never leaves a half-written file under the real name.
* :func:`estimate_bytes` / :func:`check_memory` refuse, before simulating, a
  run that would not fit in memory.

The ``avblocks run`` command itself is :mod:`avblocks.commands.run`; the
path checks a scenario's files go through (``inside``, ``safe_name``) are
:mod:`avblocks.scenarios.paths` (re-exported here).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import tempfile
from pathlib import Path

from .core.atomic import atomic_path, atomic_write_bytes  # noqa: F401  (atomic_path: as before)
from .core.errors import AvError
from .scenarios.paths import inside, safe_name  # noqa: F401  (importable here as before)

_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP")
                 if hasattr(signal, n))


class Interrupted(KeyboardInterrupt):
    """The run was stopped by a signal; ``signum`` and ``signal_name`` say which."""

    def __init__(self, signum):
        self.signum = int(signum)
        self.signal_name = signal.Signals(signum).name
        super().__init__(self.signal_name)


class SignalGuard:
    """Context manager for the whole of a CLI run.

    While *armed*, the first signal raises :class:`Interrupted` in the main
    thread; after that (or after :meth:`defer`, called once the simulation
    returned) signals are only recorded, so writing the files finishes.
    ``signum`` is the first signal received (or None); ``exit_code`` is
    ``128 + signum``.
    """

    def __init__(self):
        self.signum = None
        self.armed = True
        self._old = {}

    def _handler(self, signum, frame):
        first = self.signum is None
        if first:
            self.signum = signum
        if first and self.armed:
            self.armed = False
            raise Interrupted(signum)
        try:
            os.write(2, b"avblocks: still writing what was simulated; "
                        b"it will stop right after\n")
        except OSError:
            pass

    def defer(self):
        """From now on signals are recorded, never raised."""
        self.armed = False

    @property
    def exit_code(self):
        return None if self.signum is None else 128 + int(self.signum)

    @property
    def signal_name(self):
        return None if self.signum is None else signal.Signals(self.signum).name

    def __enter__(self):
        import threading
        if threading.current_thread() is threading.main_thread():
            for s in _SIGNALS:
                try:
                    self._old[s] = signal.signal(s, self._handler)
                except (OSError, ValueError):  # pragma: no cover - exotic platforms
                    pass
        return self

    def __exit__(self, *exc):
        for s, h in self._old.items():
            signal.signal(s, h)
        return False


def prepare_output(out) -> Path:
    """Create the output folder and prove it writable (a temporary file is
    made and removed), before anything is simulated."""
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise AvError(f"output folder '{out}' exists and is not a folder",
                      hint="pass another --out") from None
    except OSError as e:
        raise AvError(f"cannot create the output folder '{out}': "
                      f"{e.strerror or e}", hint="pass a writable --out") from None
    if not out.is_dir():
        raise AvError(f"output folder '{out}' is not a folder", hint="pass another --out")
    try:
        fd, probe = tempfile.mkstemp(prefix=".avblocks-probe-", dir=out)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise AvError(f"the output folder '{out}' is not writable: {e.strerror or e}",
                      hint="pass a writable --out (nothing was simulated)") from None
    return out


def write_text_atomic(path, text):
    return atomic_write_bytes(path, text.encode())


def say(msg):
    """One line on stderr, never raising (stderr may be closed)."""
    with contextlib.suppress(OSError, ValueError):
        print(msg, file=sys.stderr, flush=True)


def estimate_bytes(compiled, sim) -> int:
    """Memory a run needs, estimated from the declared ports before anything
    is allocated: states and outputs (about six copies of the states for
    the solver stages and two of the outputs) plus the log."""
    import numpy as np
    state = sum(np.asarray(v).nbytes for b in compiled.blocks for v in b._init.values())
    outs = sum(int(np.prod(p.shape)) * np.dtype(p.dtype).itemsize
               for b in compiled.blocks for p in b._outputs.values()
               if p.shape is not None)
    need = 6 * state + 2 * outs
    try:
        dt = float(sim.get("dt", 0.01))
        steps = (float(sim.get("t_final", 10.0)) - float(sim.get("t0", 0.0))) / dt
        every = max(1, int(sim.get("log_every") or 1))
        if np.isfinite(steps) and steps > 0:
            from .core.runguard import default_log
            log = sim.get("log") or default_log(compiled)
            log = [log] if isinstance(log, str) else list(log)
            per = 0
            for r in log:
                i, o = compiled.resolve(r)
                p = compiled.blocks[i]._outputs[o]
                per += int(np.prod(p.shape)) * np.dtype(p.dtype).itemsize
            log_bytes = int(steps // every + 1) * per
            if sim.get("log_every") is None:     # simulate() decimates to the cap
                log_bytes = min(log_bytes, int(sim.get("max_log_bytes", 2 * 1024**3)))
            need += log_bytes
    except (TypeError, ValueError, OverflowError, ZeroDivisionError, AvError):
        pass            # simulate() names the bad setting itself (dt: 0 included)
    return int(need)


def check_memory(diagram, sim):
    """Refuse, before simulating, a run whose estimate passes the memory
    limit (``AVBLOCKS_MAX_MEMORY``), with the figure."""
    from .scenarios.loader import memory_limit
    need = estimate_bytes(diagram.build(), sim)
    lim = memory_limit()
    if need > lim:
        raise AvError(f"this run would need about {need / 1e9:.3g} GB "
                      f"(states, outputs and log)",
                      expected=f"<= {lim / 1e9:.3g} GB (AVBLOCKS_MAX_MEMORY)",
                      hint="use fewer agents, a shorter run, or decimate the log "
                           "(--set simulation.log_every=10)")
