"""A viser server that refuses every request without the run's token.

viser (1.1) serves its one-file web client and its websocket on one port
through ``websockets``' ``process_request`` hook, binds ``0.0.0.0`` by
default and has no authentication. :func:`open_server` binds 127.0.0.1
unless told otherwise and puts a random token in the URL *path*
(``http://127.0.0.1:PORT/<token>/``): the client derives its websocket
address from the page address without the query string, so a path token
reaches both the HTTP request and the websocket handshake. A request whose
first path segment is not the token gets ``403 Forbidden``; a good one is
handed to viser with the token segment removed.

viser builds its ``websockets`` server inside its own thread, so the check
is installed by lending viser's module a ``websockets`` namespace whose
``asyncio.server.serve`` wraps ``process_request``, for the few
milliseconds of ``ViserServer()`` construction (under a lock; nothing else
is touched). If a later viser changes how it starts its server, the check
fails loudly instead of serving without a token.
"""

from __future__ import annotations

import contextlib
import http
import io
import threading
import types

from ...core.errors import AvError
from ...core.urltoken import make_token, under_token

_LOCK = threading.Lock()


class LiveViewError(AvError):
    """The live view could not start (missing extra, viser changed...)."""


def _import_viser():
    try:
        import viser
        import viser.infra._infra as infra
        import websockets.asyncio.server as ws_server
        from websockets.http11 import Request
    except ImportError as e:
        raise LiveViewError(f"the live view needs viser ({e})",
                            hint="pip install 'avblocks[live]'") from None
    return viser, infra, ws_server, Request


class _Namespace(types.SimpleNamespace):
    """Attributes given here, the rest from ``base``."""

    def __init__(self, base, **over):
        super().__init__(**over)
        object.__setattr__(self, "_base", base)

    def __getattr__(self, name):
        return getattr(object.__getattribute__(self, "_base"), name)


def _guard(process_request, token, Request):
    """``process_request`` that checks the token segment first."""

    def check(connection, request):
        head, sep, rest = request.path.partition("?")
        after = under_token(head, token)
        if after is None:
            return connection.respond(http.HTTPStatus.FORBIDDEN,
                                      "avblocks live view: wrong or missing token\n")
        new = Request(path=(after or "/") + (sep + rest if sep else ""),
                      headers=request.headers)
        if process_request is None:
            return None
        return process_request(connection, new)

    return check


def open_server(host="127.0.0.1", port=0, token=None, label=None):
    """A started ``viser.ViserServer`` bound to ``host:port`` (0: a free
    port) that answers only under ``/<token>/``. Returns ``(server, token)``."""
    viser, infra, ws_server, Request = _import_viser()
    token = make_token(token, LiveViewError)
    real = getattr(infra, "websockets", None)
    if real is None or getattr(real, "asyncio", None) is None:
        raise LiveViewError("this viser version starts its server differently; "
                            "the live view cannot protect it with a token",
                            hint="install viser 1.1.x (pip install 'avblocks[live]')")
    installed = []

    class _Serve(ws_server.serve):
        def __init__(self, *a, process_request=None, **kw):
            installed.append(True)
            super().__init__(*a, process_request=_guard(process_request, token, Request),
                             **kw)

    server_ns = _Namespace(ws_server, serve=_Serve)
    lent = _Namespace(real, asyncio=_Namespace(real.asyncio, server=server_ns))
    with _LOCK:
        infra.websockets = lent
        try:
            # viser prints a banner with the token-less address: keep it quiet
            with contextlib.redirect_stdout(io.StringIO()):
                srv = viser.ViserServer(host=host, port=int(port), label=label,
                                        verbose=False)
        finally:
            infra.websockets = real
    if not installed:
        srv.stop()
        raise LiveViewError("could not install the token check on viser's server",
                            hint="install viser 1.1.x (pip install 'avblocks[live]')")
    return srv, token
