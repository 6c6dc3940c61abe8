"""The robots' signal guard (``interfaces.flight._guard``): a signal that
comes while the main thread holds a lock the stop needs (a flight-log line
being written, a set-point being sent) neither deadlocks the process nor
skips the stop; without such a lock the stop is done before the handler
raises. Driven by calling the installed handler, as Python does between
two bytecodes of the main thread."""

import signal
import threading
import time

import pytest

from avblocks.interfaces.flight import _guard


class _Robot:
    """Stands for a fleet block: its stop takes the lock its log takes."""

    def __init__(self):
        self.lock = threading.Lock()
        self.stopped = []

    def stop_robots(self):
        got = self.lock.acquire(timeout=5.0)     # the old handler: 5 s, then gives up
        self.stopped.append((got, threading.current_thread() is threading.main_thread()))
        if got:
            self.lock.release()


@pytest.fixture
def robot():
    r = _Robot()
    _guard.register(r)
    yield r
    _guard.unregister(r)


def test_a_signal_while_the_main_thread_holds_the_log_lock_stops_after_it(robot):
    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        with robot.lock:                         # the main thread writes a log line
            signal.getsignal(signal.SIGINT)(signal.SIGINT, None)
    deadline = time.monotonic() + 5.0
    while not robot.stopped and time.monotonic() < deadline:
        time.sleep(0.01)
    # the stop took the lock once the interrupt released it, on its own thread
    assert robot.stopped == [(True, False)]
    assert time.monotonic() - t0 < 2.0


def test_without_a_held_lock_the_stop_is_done_before_the_interrupt(robot):
    with pytest.raises(KeyboardInterrupt):
        signal.getsignal(signal.SIGTERM)(signal.SIGTERM, None)
    assert robot.stopped == [(True, False)]


def test_the_previous_handlers_come_back_when_the_last_robot_stops():
    before = signal.getsignal(signal.SIGINT)
    r = _Robot()
    _guard.register(r)
    assert signal.getsignal(signal.SIGINT) is _guard._handler
    _guard.unregister(r)
    assert signal.getsignal(signal.SIGINT) is before


def test_a_handler_installed_over_the_guards_is_chained_by_the_next_robot():
    """A run that ended with its robot still registered, then someone's own
    handler that only takes note (a CLI run's deferred guard): the next
    robot puts the guard back on top, so a signal stops it and still
    reaches the other handler; when the robots stop, that handler is back."""
    before = signal.getsignal(signal.SIGINT)
    seen = []

    def noting(signum, frame):
        seen.append(signum)

    left, r = _Robot(), _Robot()
    _guard.register(left)                        # never unregistered by its run
    try:
        signal.signal(signal.SIGINT, noting)
        _guard.register(r)
        assert signal.getsignal(signal.SIGINT) is _guard._handler
        with pytest.raises(KeyboardInterrupt):
            signal.getsignal(signal.SIGINT)(signal.SIGINT, None)
        assert seen == [signal.SIGINT]
        assert (True, False) in r.stopped
    finally:
        _guard.unregister(r)
        _guard.unregister(left)
    assert signal.getsignal(signal.SIGINT) is noting
    signal.signal(signal.SIGINT, before)


def test_a_handler_installed_after_the_guards_is_not_undone_when_robots_stop():
    before = signal.getsignal(signal.SIGINT)
    r = _Robot()
    _guard.register(r)

    def later(signum, frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, later)
    _guard.unregister(r)
    assert signal.getsignal(signal.SIGINT) is later
    signal.signal(signal.SIGINT, before)


def test_an_inherited_ignore_still_stops_the_run():
    """A process started in the background inherits "ignore SIGINT"; a
    SIGINT sent to it while robots fly stops them and ends the run (it
    used to stop them and let the run go on commanding them: seen as a
    fleet that kept flying after Ctrl-C when the suite ran in a background
    job)."""
    before = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    r = _Robot()
    try:
        _guard.register(r)
        with pytest.raises(KeyboardInterrupt):
            signal.getsignal(signal.SIGINT)(signal.SIGINT, None)
        assert r.stopped == [(True, False)]
        _guard.unregister(r)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        _guard.unregister(r)
        signal.signal(signal.SIGINT, before)
