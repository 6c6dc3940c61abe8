"""Stop every robot whatever ends the process.

The robot blocks register here while a run is on. On SIGTERM (and SIGINT)
the handler first commands every registered robot to zero velocity, then
hands the signal to the handler that was there before (the CLI's guard
raises its own interrupt), and raises :class:`KeyboardInterrupt` in the main
thread, even when the signal was ignored before (a process started in the
background inherits "ignore SIGINT"; a run that went on after the stop would
command the robots again). The stop runs on a thread of its own, which the
handler waits for up to :data:`STOP_WAIT`: a handler runs in the main thread
between two of its bytecodes, so a lock that thread holds when the signal
comes (a flight-log line being written, a set-point being sent) would
deadlock a stop made in the handler itself; the interrupt releases it, and
the stop goes out after what the main thread was sending. So that
``simulate()`` takes its interrupted path: it returns the results logged so
far (the CLI saves them) after calling every block's ``on_stop`` (which
stops the robots again). An ``atexit`` hook stops any block still registered
when the interpreter exits. Handlers are installed only from the main thread
(again by a block that finds another handler over the guard's) and the
previous ones are restored when the last block stops, unless another handler
was installed over the guard's since.
"""

from __future__ import annotations

import atexit
import signal
import threading
import weakref

_live = weakref.WeakSet()
_previous = {}
_lock = threading.Lock()
_atexit_done = False


def _stop_all():
    for b in list(_live):
        try:
            b.stop_robots()
        except Exception:  # noqa: BLE001 - stopping the others matters more
            pass


#: seconds the signal handler waits for the robots' stop before it raises
#: in the main thread (the stop goes on after that if a lock held it back)
STOP_WAIT = 0.2


def _handler(signum, frame):
    # not a daemon: the interpreter waits for the stop before it exits
    stop = threading.Thread(target=_stop_all, name="avblocks-signal-stop")
    stop.start()
    stop.join(STOP_WAIT)
    prev = _previous.get(signum)
    if callable(prev):          # e.g. the CLI's guard: it raises its own interrupt
        prev(signum, frame)
    # also when the signal was ignored before (a process started in the
    # background inherits "ignore SIGINT"): the robots were just stopped,
    # and a run that went on would command them again (as the console
    # entry point, which replaces an inherited ignore)
    raise KeyboardInterrupt(f"signal {signum}")


def register(block):
    global _atexit_done
    with _lock:
        if not _atexit_done:
            atexit.register(_stop_all)
            _atexit_done = True
        _live.add(block)
        if threading.current_thread() is threading.main_thread():
            # not only for the first block: a handler installed over ours
            # while robots were registered (a block left registered by a
            # run that ended without stopping it) would take the signal
            # without stopping them; ours goes back on top and chains to it
            for s in (signal.SIGTERM, signal.SIGINT):
                try:
                    if signal.getsignal(s) is not _handler:
                        _previous[s] = signal.signal(s, _handler)
                except (ValueError, OSError):  # pragma: no cover
                    pass


def unregister(block):
    with _lock:
        _live.discard(block)
        if not _live and threading.current_thread() is threading.main_thread():
            for s, h in list(_previous.items()):
                try:
                    # a handler installed after ours stays: its owner puts
                    # back what it found when it is done
                    if signal.getsignal(s) is _handler:
                        signal.signal(s, h)
                except (ValueError, OSError, TypeError):  # pragma: no cover
                    pass
            _previous.clear()
