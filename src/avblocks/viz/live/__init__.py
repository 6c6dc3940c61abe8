"""Live, interactive runs in the browser (extra ``[live]``: viser).

::

    import avblocks as av
    res = av.simulate(diagram, t_final=60, live=True)      # prints the URL
    view = av.viz.live.LiveView(diagram, t_final=60).start()   # notebook
    view                                                   # the page inline
    res = view.wait()

See :mod:`avblocks.viz.live.view` for what the page shows and how a run
ends, and ``docs/live.md``.
"""

from ._server import LiveViewError, open_server
from .controls import SPEEDS
from .engine import simulate_live
from .estop import EStop
from .view import LiveView

__all__ = ["LiveView", "EStop", "simulate_live", "LiveViewError", "open_server", "SPEEDS"]
