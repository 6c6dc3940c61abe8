"""The ``avblocks`` console command's entry point, kept outside the package.

Importing anything under ``avblocks`` first imports the package (NumPy,
SciPy, the block library: most of a second). A Ctrl-C in that time used to
end in a ``KeyboardInterrupt`` traceback, or be lost altogether when the
shell started the command with SIGINT ignored (a background job of a
script). This module imports only :mod:`signal` and :mod:`sys`, installs a
SIGINT handler, and only then imports :func:`avblocks.cli.main`; a Ctrl-C
at any moment before the run's own signal guard takes over ends the
command with one line, ``avblocks: interrupted``, and exit status 130.

An inherited "ignore SIGINT" is replaced: whoever presses Ctrl-C (or sends
SIGINT) expects the run to stop, and the run's guard saves what was
simulated (see docs/safety.md).
"""

import signal
import sys


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def _say(msg):
    try:
        print(msg, file=sys.stderr, flush=True)
    except (OSError, ValueError):   # stderr closed
        pass


def main(argv=None):
    """Run ``avblocks`` with ``argv`` (default ``sys.argv[1:]``); the exit status."""
    try:
        signal.signal(signal.SIGINT, _interrupt)
    except (OSError, ValueError):   # not the main thread: nothing to guard
        pass
    try:
        from avblocks.cli import main as cli_main
        return cli_main(argv)
    except KeyboardInterrupt:
        _say("avblocks: interrupted")
        return 130


if __name__ == "__main__":
    sys.exit(main())
