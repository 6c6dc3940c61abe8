"""``avblocks edit [NAME | FILE]``: draw, wire and run a diagram in the browser.

    avblocks edit                      # an empty diagram
    avblocks edit formation            # a built-in case study
    avblocks edit my_scenario.yaml     # a scenario file
    avblocks edit ../other/x.yaml      # anywhere: the editor works in that file's folder
    avblocks edit --no-browser --port 8765 --blocks mypackage.blocks

Serves the editor (:mod:`avblocks.editor.server`) on 127.0.0.1 with a
random token in the URL, prints the URL, opens it in the browser unless
``--no-browser``, and runs until Ctrl-C. The editor reads and writes files
only under one folder: that of the file it opens, else the folder it was
started in.
"""

from __future__ import annotations

import sys
from pathlib import Path


def add_parser(sub):
    """The ``edit`` sub-command on an argparse sub-parser set."""
    e = sub.add_parser("edit", help="draw, wire and run a diagram in the browser editor")
    e.add_argument("target", nargs="?",
                   help="built-in case study or scenario file to open (none: an empty "
                        "diagram)")
    e.add_argument("--no-browser", action="store_true", dest="no_browser",
                   help="only print the URL")
    e.add_argument("--port", type=int, default=0,
                   help="port on 127.0.0.1 (default: a free one)")
    e.add_argument("--blocks", nargs="+", default=[], metavar="MODULE",
                   help="importable modules whose blocks join the palette")
    e.set_defaults(fn=cmd_edit)
    return e


def cmd_edit(args):
    from ..editor.server import EditorServer
    from ..editor.service import EditorError, EditorService
    root = Path.cwd()
    target = Path(args.target) if args.target else None
    if target is not None and target.is_file():
        # a file anywhere the user can name: the editor's folder is that file's
        # own (it reads and writes only there, as it would in this folder)
        root = target.resolve().parent
    service = EditorService(root, extra_modules=args.blocks)
    server = None
    with _StopSignals() as signals:
        try:
            if args.target:
                from ..scenarios.loader import builtin_scenarios
                if target.is_file():
                    service.initial = {"path": target.resolve().name}
                elif args.target in builtin_scenarios():
                    service.load(builtin=args.target)          # a Python-only one is refused
                    service.initial = {"builtin": args.target}
                else:
                    raise EditorError(f"no scenario file or built-in case study "
                                      f"'{args.target}'",
                                      hint=f"built-in: {sorted(builtin_scenarios())}")
            server = EditorServer(service, port=args.port).start()
            _serve(server, args)
        finally:
            # runs cancelled, live views stopped, the runs' folders and any
            # temporary file still being written removed (after SIGTERM too);
            # a signal from here on is ignored so that this runs to its end
            signals.hold()
            if server is not None:
                server.stop()
            else:
                service.close()
    print("avblocks editor: stopped", file=sys.stderr)
    return 0


def _serve(server, args):
    import time
    print(f"avblocks editor: {server.url}", flush=True)
    print("(Ctrl-C to stop)", flush=True)
    if not args.no_browser:
        import webbrowser
        try:
            webbrowser.open(server.url)
        except Exception:  # noqa: BLE001 - no browser: the URL is printed
            pass
    try:
        while server._thread.is_alive():
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass


class _StopSignals:
    """``with _StopSignals() as s``: SIGINT (Ctrl-C), SIGTERM and SIGHUP
    (those this system has: :func:`avblocks.core.confined.stop_signals`)
    raise ``KeyboardInterrupt`` in the main thread, so the editor stops
    through its ``finally``; after :meth:`hold` they are ignored (the
    clean-up runs to its end). The previous handlers come back on exit."""

    def __enter__(self):
        import signal

        from ..core.confined import stop_signals
        self._old = {}
        self._held = False

        def stop(signum, frame):
            if not self._held:
                self._held = True
                raise KeyboardInterrupt

        for sig in stop_signals():
            try:
                self._old[sig] = signal.signal(sig, stop)
            except (OSError, ValueError):     # not the main thread
                pass
        return self

    def hold(self):
        """From now on a stop signal is ignored."""
        self._held = True

    def __exit__(self, *exc):
        import signal
        for sig, old in self._old.items():
            try:
                signal.signal(sig, old if old is not None else signal.SIG_DFL)
            except (OSError, ValueError, TypeError):
                pass
        return False
