"""Live views opened from the page: the drawn diagram running in the live
view (:mod:`avblocks.viz.live`), each on its own loopback port."""

from __future__ import annotations

from .errors import EditorError


class LiveViews:
    """The live views one editor started; :meth:`close` stops them all."""

    def __init__(self):
        self._views = []

    def open(self, diagram, sim) -> dict:
        """Start a live view of ``diagram`` with the scenario's simulate
        keywords ``sim``; ``{url}``."""
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
        view.start()
        self._views = [v for v in self._views if v._thread and v._thread.is_alive()]
        self._views.append(view)
        return {"url": view.url}

    def __iter__(self):
        return iter(list(self._views))

    def __getitem__(self, i):
        return self._views[i]

    def close(self):
        """Stop every live view."""
        for v in self._views:
            v.stop()
