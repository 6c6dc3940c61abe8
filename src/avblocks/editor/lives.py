"""Live views opened from the page: the drawn diagram running in the live
view (:mod:`avblocks.viz.live`), each on its own loopback port.

Each view listens (a socket and a few threads) until its run ends: the run
reaches its end with no page open, its page is closed, the page asks
(``POST live/stop``) or the editor closes. At most :data:`MAX_LIVE` are
kept: opening one more stops the oldest first.
"""

from __future__ import annotations

import threading

from .errors import EditorError

#: Live views listening at once; one more stops the oldest.
MAX_LIVE = 2
#: Seconds a view is given to stop (its run ends, its server closes).
STOP_TIMEOUT = 10.0


class LiveViews:
    """The live views one editor started; :meth:`close` stops them all."""

    def __init__(self):
        self._views = []
        self._lock = threading.Lock()

    def _alive(self):
        return [v for v in self._views if v._thread is not None and v._thread.is_alive()]

    def open(self, diagram, sim) -> dict:
        """Start a live view of ``diagram`` with the scenario's simulate
        keywords ``sim`` (the oldest one stopped first when
        :data:`MAX_LIVE` are running); ``{url}``."""
        try:
            from ..viz.live import LiveView
        except ImportError as e:
            raise EditorError(f"the live view needs its extra ({e})",
                              kind="MissingExtra", hint='pip install "avblocks[live]"'
                              ) from None
        sim = dict(sim)
        t_final = float(sim.pop("t_final", 10.0))
        keep = {k: sim[k] for k in ("dt", "solver", "seed", "log", "log_every", "params",
                                    "realtime") if k in sim}
        view = LiveView(diagram, t_final, verbose=False, **keep)
        with self._lock:
            self._views = self._alive()
            old = self._views[:max(0, len(self._views) - MAX_LIVE + 1)]
            self._views = self._views[len(old):]
        for v in old:
            _stop(v)
        view.start()
        with self._lock:
            self._views.append(view)
        return {"url": view.url}

    def stop(self, url=None) -> list:
        """Stop the view at ``url`` (404 ``NotFound`` for a URL this editor
        did not open), or every one when None; the URLs stopped."""
        with self._lock:
            if url is None:
                gone, self._views = self._views, []
            else:
                gone = [v for v in self._views if v.url == url]
                if not gone:
                    raise EditorError(f"no live view at '{str(url)[:200]}'", status=404,
                                      kind="NotFound")
                self._views = [v for v in self._views if v.url != url]
        for v in gone:
            _stop(v)
        return [v.url for v in gone]

    def __iter__(self):
        return iter(list(self._views))

    def __getitem__(self, i):
        return self._views[i]

    def __len__(self):
        return len(self._alive())

    def close(self):
        """Stop every live view."""
        self.stop(None)


def _stop(view):
    """End a view's run and wait for its server to close."""
    try:
        view.close(timeout=STOP_TIMEOUT)
    except Exception:  # noqa: BLE001 - the run's own error: it has ended anyway
        pass
