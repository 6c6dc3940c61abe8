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

_interrupted = []


def _interrupt(signum, frame):
    _interrupted.append(signum)
    raise KeyboardInterrupt


def _quiet(hook):
    """``sys.unraisablehook`` that drops a KeyboardInterrupt. The handler's
    exception can land where Python cannot raise it (a weak reference's
    callback of the import machinery, ``_get_module_lock``): Python then
    prints "Exception ignored in ..." with a traceback and goes on, so the
    command would have run to its end (seen once in CI). The handler has
    noted the interrupt; :func:`main` acts on it after the import."""
    def quiet(unraisable):
        if not isinstance(unraisable.exc_value, KeyboardInterrupt):
            hook(unraisable)
    return quiet


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
        hook = sys.unraisablehook
        sys.unraisablehook = _quiet(hook)
        try:
            from avblocks.cli import main as cli_main
        finally:
            sys.unraisablehook = hook
        if _interrupted:            # an interrupt Python could not raise
            raise KeyboardInterrupt
        return cli_main(argv)
    except KeyboardInterrupt:
        _say("avblocks: interrupted")
        return 130


if __name__ == "__main__":
    sys.exit(main())
