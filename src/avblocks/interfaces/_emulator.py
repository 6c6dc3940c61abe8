"""Running an emulator from the command line: the part the ``... emulate``
commands (``robots``, ``mavlink``, ``crazyflies``) share."""

from __future__ import annotations

import signal
import threading


def run_emulator(em, banner, duration=None) -> int:
    """Run emulator ``em`` (an object with ``run(duration)``, ``stop()`` and
    ``close()``) in the foreground until ``duration`` wall seconds have
    passed (None: until stopped), Ctrl-C or SIGTERM: print ``banner``
    (flushed, so a parent process reading the output knows it is up), run,
    and close it however the run ended. SIGTERM asks the run to stop (its
    loop ends at the next tick); the previous handler is put back after.
    Returns the exit status, 0."""
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, lambda *a: em.stop())
    print(banner, flush=True)
    try:
        em.run(duration)
    except KeyboardInterrupt:
        pass
    finally:
        em.close()
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return 0
