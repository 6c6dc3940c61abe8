"""The editor's HTTP server: a small Starlette app on 127.0.0.1 behind a token.

The page is served at ``http://127.0.0.1:PORT/<token>/`` (the token is a
random URL-safe string, as the live view's). Every request passes, in
this order:

1. :class:`Guard` (in front of everything): the ``Host`` header must name
   a loopback address (``127.0.0.1``, ``localhost``, ``[::1]``) with the
   served port (400 ``BadHost`` otherwise: a DNS-rebinding page), and an
   ``Origin`` header, when sent, must be this server's own origin (403
   ``CrossOrigin``: another web page the user visits); every response,
   errors and the token's 403 included, carries the
   :data:`SECURITY_HEADERS` (Content-Security-Policy, ``Referrer-Policy:
   no-referrer``, ``X-Content-Type-Options: nosniff``, ...);
2. :class:`TokenGate`: a request whose first path segment is not the token
   gets ``403`` before anything else looks at it;
3. the routes: a POST must be ``Content-Type: application/json`` (415
   ``UnsupportedMediaType``: a cross-origin form or ``text/plain`` POST
   is not one), its body is read chunk by chunk and refused past
   :data:`MAX_BODY` bytes without reading on (413 ``TooLarge``, chunked
   bodies too), and scanned for nesting deeper than
   :data:`MAX_JSON_DEPTH` and more than :data:`MAX_JSON_VALUES` values
   before it is parsed (400 ``BadRequest``; a body is UTF-8 text).

Below all of them, the connection itself (:func:`bounded_protocol`): a
request must arrive whole within :data:`REQUEST_TIMEOUT` seconds, at most
:data:`MAX_CONNECTIONS` connections are held and
:data:`MAX_BODIES_READING` bodies read at once.

Under the token:

* ``/`` and ``/assets/...``: the built front end (``editor/static/``);
* ``GET api/palette``, ``GET api/files``, ``GET api/new``;
* ``POST api/<op>`` with a JSON body: ``load``, ``validate``, ``save``,
  ``run``, ``live``, ``export``; ``POST api/live/stop``;
* ``GET api/run/<run>``, ``POST api/run/<run>/cancel``,
  ``GET api/run/<run>/signal?name=...``, ``GET api/run/<run>/file/<name>``.

The operations are those of :class:`~avblocks.editor.service.EditorService`
(see ``API.md``); every error, unknown routes included, comes back as
``{"error": {"message", "kind"}}`` with a 4xx status. :class:`EditorServer`
runs uvicorn in a background thread.
"""

from __future__ import annotations

import asyncio
import json
import re
import socket
import threading
from pathlib import Path

from ..core.errors import AvError
from ..core.urltoken import make_token, under_token
from .service import EditorError, EditorService, error_json

#: Where the built front end lies (``index.html``, ``assets/``, ``widget.js``).
STATIC = Path(__file__).parent / "static"
#: Request bodies larger than this are refused (413), read no further.
MAX_BODY = 8 * 1024 * 1024
#: Deepest nesting of a request's JSON (objects and arrays inside each
#: other; a scenario's values nest at most 100 levels).
MAX_JSON_DEPTH = 100
#: Most values (numbers, texts, arrays, objects) in a request's JSON.
MAX_JSON_VALUES = 1_000_000
#: Seconds a client has to send a whole request (its headers and body) from
#: the moment it connected or its previous answer was sent; a slower one is
#: cut off (a "slowloris" holds a connection, and its body's memory, as
#: long as it likes otherwise). Time the editor spends answering does not
#: count.
REQUEST_TIMEOUT = 30.0
#: Connections held at once. A new one past it cuts off the oldest
#: connection that is still sending its request (or idle); when every
#: connection is being answered, the new one is refused.
MAX_CONNECTIONS = 64
#: Request bodies read at the same time (each at most :data:`MAX_BODY`):
#: the others wait their turn, so slow uploads hold at most this many
#: bodies' memory.
MAX_BODIES_READING = 8
#: The host names the server answers to, with its port: loopback only.
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")
#: The page's Content-Security-Policy: scripts, styles, fetches only from
#: the server itself, no inline script, never framed. ``img-src`` takes
#: ``data:`` (the favicon, exported pictures).
CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; "
       "img-src 'self' data: blob:; font-src 'self' data:; connect-src 'self'; "
       "worker-src 'self' blob:; object-src 'none'; base-uri 'none'; form-action 'none'; "
       "frame-ancestors 'none'")
#: Headers every response carries (errors and the token's 403 included).
SECURITY_HEADERS = (
    (b"content-security-policy", CSP.encode()),
    (b"referrer-policy", b"no-referrer"),
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"DENY"),
    (b"cross-origin-resource-policy", b"same-origin"),
    (b"cache-control", b"no-store"),
)


class EditorServerError(AvError):
    """The editor could not start (missing extra, port taken...)."""


def _imports():
    try:
        import starlette  # noqa: F401
        import uvicorn  # noqa: F401
    except ImportError as e:
        raise EditorServerError(f"the editor needs starlette and uvicorn ({e})",
                                hint='pip install "avblocks[editor]"') from None


async def _answer(send, status, body: bytes, ctype=b"application/json", extra=()):
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", ctype),
                            (b"content-length", str(len(body)).encode()), *extra]})
    await send({"type": "http.response.body", "body": body})


def _json_error(message, kind) -> bytes:
    return json.dumps({"error": {"message": message, "kind": kind}}).encode()


class Guard:
    """ASGI middleware in front of every handler (Starlette's
    ``TrustedHostMiddleware`` is the model): ``Host`` must be a loopback
    name with the served ``port`` (None: any port), ``Origin`` when sent
    must be ``http://`` + such a host, a cross-site request that is not a
    navigation is refused; every response gets :data:`SECURITY_HEADERS`.

    Parameters
    ----------
    app : ASGI app
    port : int or None
    names : sequence of str
        Host names besides :data:`LOOPBACK_NAMES` (the address the server
        was bound to when it is another one).
    """

    def __init__(self, app, port=None, names=()):
        self.app = app
        self.port = port
        names = {n.lower() for n in (*LOOPBACK_NAMES, *names)}
        self.hosts = names
        self.origins = {f"http://{n}" for n in names}
        if port is not None:
            self.hosts = {f"{n}:{port}" for n in names}
            self.origins = {f"http://{n}:{port}" for n in names}
            if int(port) == 80:
                self.hosts |= names
                self.origins |= {f"http://{n}" for n in names}

    def _host_ok(self, host: str) -> bool:
        host = host.strip().lower()
        if self.port is None:
            name = host.rsplit(":", 1)[0] if not host.endswith("]") else host
            return name in self.hosts
        return host in self.hosts

    async def __call__(self, scope, receive, send):
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        headers = {}
        for k, v in scope.get("headers") or ():
            headers.setdefault(k.decode("latin-1").lower(), []).append(v.decode("latin-1"))

        async def secured(message):
            if message["type"] == "http.response.start":
                have = {k.lower() for k, _v in message.get("headers") or ()}
                message = dict(message)
                message["headers"] = [*(message.get("headers") or ()),
                                      *(h for h in SECURITY_HEADERS if h[0] not in have)]
            await send(message)

        host = headers.get("host", [])
        origin = headers.get("origin", [])
        why = None
        if len(host) != 1 or not self._host_ok(host[0]):
            why = (400, "BadHost", "the editor answers only to 127.0.0.1, localhost or "
                                   "[::1] with its port in the Host header")
        elif len(origin) > 1 or (origin and origin[0].strip().lower() not in self.origins):
            why = (403, "CrossOrigin", "a request from another web page (Origin "
                                       f"{origin[0][:80]!r}) is refused" if origin else
                   "several Origin headers")
        elif headers.get("sec-fetch-site", [""])[0] == "cross-site" and \
                headers.get("sec-fetch-mode", [""])[0] not in ("navigate", ""):
            why = (403, "CrossOrigin", "a cross-site request is refused")
        if why is not None:
            if scope["type"] == "websocket":
                await send({"type": "websocket.close", "code": 1008})
                return
            await _answer(secured, why[0], _json_error(why[2], why[1]))
            return
        return await self.app(scope, receive, secured)


class TokenGate:
    """ASGI wrapper: 403 unless the first path segment is the token; the
    token segment is removed before the app sees the path."""

    def __init__(self, app, token):
        self.app = app
        self.token = token
        self.prefix = f"/{token}".encode()

    async def __call__(self, scope, receive, send):
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        raw = scope.get("raw_path") or scope["path"].encode()
        after = under_token(raw.split(b"?", 1)[0], self.token)
        if after is None:
            if scope["type"] == "websocket":
                await send({"type": "websocket.close", "code": 1008})
                return
            await _answer(send, 403, b"avblocks editor: wrong or missing token\n",
                          b"text/plain; charset=utf-8")
            return
        if after == b"":          # /<token> -> /<token>/ so relative URLs work
            await _answer(send, 307, b"", b"text/plain", [(b"location", self.prefix + b"/")])
            return
        scope = dict(scope)
        scope["path"] = scope["path"][len(self.prefix):]
        scope["raw_path"] = after
        scope["root_path"] = scope.get("root_path", "") + self.prefix.decode()
        return await self.app(scope, receive, send)


_Guard = Guard          # the names before issue 42
_TokenGate = TokenGate

# a JSON string (escapes included), matched without backtracking
_JSON_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.S)


def json_shape(raw: bytes) -> tuple[int, int]:
    """``(depth, values)`` of JSON text, counted on its brackets and commas
    outside strings, without parsing it (so that a body nested 100,000
    levels never reaches a recursive parser)."""
    import numpy as np
    if not raw:
        return 0, 0
    bare = _JSON_STRING.sub(b'""', raw)
    a = np.frombuffer(bare, dtype=np.uint8)
    opens = (a == 0x5B) | (a == 0x7B)
    closes = (a == 0x5D) | (a == 0x7D)
    depth = int(np.cumsum(opens.astype(np.int64) - closes).max(initial=0))
    values = int(opens.sum()) + int((a == 0x2C).sum()) + 1
    return depth, values


def parse_body(raw: bytes) -> dict:
    """The JSON object of a request body, within :data:`MAX_JSON_DEPTH` and
    :data:`MAX_JSON_VALUES` (checked before parsing); an
    :class:`EditorError` (400 ``BadRequest``) otherwise. Empty: ``{}``.

    The body must be UTF-8 text (RFC 8259, section 8.1), without a
    byte-order mark: it is decoded first and the text is parsed, so the
    depth scan and the parser read the same characters (``json.loads`` of
    bytes would also take UTF-16 and UTF-32, where an escaped quote put
    the scan out of step with the parser and hid the nesting)."""
    if not raw.strip():
        return {}
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise EditorError(f"the body is not UTF-8 text (byte {e.start}): JSON is sent "
                          "as UTF-8", kind="BadRequest") from None
    depth, values = json_shape(raw)
    if depth > MAX_JSON_DEPTH:
        raise EditorError(f"the body nests deeper than {MAX_JSON_DEPTH} levels",
                          kind="BadRequest")
    if values > MAX_JSON_VALUES:
        raise EditorError(f"the body holds more than {MAX_JSON_VALUES:,} values",
                          kind="BadRequest")

    try:
        # NaN and Infinity are read as Python's json writes them: a field
        # where `.nan` or `1e999` is typed sends that number, and the library
        # judges it (its message comes back on that field)
        data = json.loads(text)
    except (ValueError, RecursionError) as e:
        raise EditorError(f"the body is not JSON: {str(e)[:200]}", kind="BadRequest"
                          ) from None
    if not isinstance(data, dict):
        raise EditorError("the body is a JSON object of arguments", kind="BadRequest")
    return data


async def read_body(request) -> bytes:
    """The body of ``request``, read chunk by chunk and refused (413
    ``TooLarge``) as soon as it passes :data:`MAX_BODY`: an announced
    ``Content-Length`` over it is refused before anything is read, a
    chunked one when the cap is reached (the rest is never read)."""
    announced = request.headers.get("content-length")
    if announced is not None:
        try:
            n = int(announced)
        except ValueError:
            raise EditorError("Content-Length is not a number", kind="BadRequest") from None
        if n > MAX_BODY:
            raise EditorError(f"request too large: {n:,} bytes, more than {MAX_BODY:,}",
                              status=413, kind="TooLarge")
    from starlette.requests import ClientDisconnect
    buf = bytearray()
    try:
        async for chunk in request.stream():
            buf += chunk
            if len(buf) > MAX_BODY:
                raise EditorError(f"request too large: more than {MAX_BODY:,} bytes",
                                  status=413, kind="TooLarge")
    except ClientDisconnect:
        # the client went away, or was cut off for being slow: no answer
        # can reach it, and nothing of the body is kept
        raise EditorError("the client went away while sending its request",
                          kind="BadRequest") from None
    return bytes(buf)


def _is_json(request) -> bool:
    ctype = request.headers.get("content-type", "")
    return ctype.split(";", 1)[0].strip().lower() == "application/json"


def make_app(service: EditorService, token: str, port=None, names=()):
    """The ASGI app (guard and token gate included) serving ``service``
    on ``port`` (None: any port of a loopback name)."""
    _imports()
    from starlette.applications import Starlette
    from starlette.exceptions import HTTPException
    from starlette.responses import FileResponse, HTMLResponse, Response
    from starlette.responses import JSONResponse as _JSONResponse
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    class JSONResponse(_JSONResponse):
        """JSON as Python writes it: a draft saved with ``.nan`` comes back
        with ``NaN`` (the page reads it outside strings)."""

        def render(self, content) -> bytes:
            return json.dumps(content, ensure_ascii=False, allow_nan=True,
                              separators=(",", ":")).encode("utf-8")

    def failed(e: BaseException):
        status, body = error_json(e)
        headers = {"connection": "close"} if status == 413 else None
        return JSONResponse(body, status_code=status, headers=headers)

    async def call(fn, *a, **kw):
        try:
            result = await asyncio.to_thread(fn, *a, **kw)
        except (AvError, Exception) as e:  # noqa: BLE001 - every failure as JSON
            return failed(e)
        if isinstance(result, bytes):
            return Response(result, media_type="image/png")
        return JSONResponse(result)

    slots = []                  # the semaphore, made in the server's own loop

    async def body_of(request) -> dict:
        if not _is_json(request):
            raise EditorError("a POST's body is JSON: send it with Content-Type: "
                              "application/json", status=415, kind="UnsupportedMediaType")
        if not slots:
            slots.append(asyncio.Semaphore(MAX_BODIES_READING))
        async with slots[0]:
            raw = await read_body(request)
        return parse_body(raw)

    async def index(request):
        page = STATIC / "index.html"
        if not page.is_file():
            return HTMLResponse("<!doctype html><title>avblocks editor</title>"
                                "<p>The editor's front end is not built "
                                "(src/avblocks/editor/web: npm ci &amp;&amp; npm run "
                                "build).</p>", status_code=500)
        return FileResponse(page, headers={"cache-control": "no-store"})

    async def get_op(request):
        op = request.path_params["op"]
        if op not in ("palette", "files", "new"):
            return failed(EditorError(f"GET {op[:80]}: use POST", status=405,
                                      kind="MethodNotAllowed"))
        return await call(service.call, op, {})

    async def post(request, op, extra=None):
        try:
            args = await body_of(request)
        except EditorError as e:
            return failed(e)
        if extra:
            for k, v in extra.items():
                if k in args and args[k] != v:
                    return failed(EditorError(f"'{k}' is given by the URL",
                                              kind="BadRequest"))
                args[k] = v
        return await call(service.call, op, args)

    async def post_op(request):
        op = request.path_params["op"]
        if op in ("palette", "files", "new"):
            return failed(EditorError(f"POST {op}: use GET", status=405,
                                      kind="MethodNotAllowed"))
        return await post(request, op)

    async def live_stop(request):
        return await post(request, "live_stop")

    async def run_status(request):
        return await call(service.call, "status", {"run": request.path_params["run"]})

    async def run_cancel(request):
        return await post(request, "cancel", {"run": request.path_params["run"]})

    async def run_signal(request):
        return await call(service.call, "signal",
                          {"run": request.path_params["run"],
                           "name": request.query_params.get("name", "")})

    async def run_file(request):
        return await call(service.figure, request.path_params["run"],
                          request.path_params["name"])

    async def no_favicon(request):
        return Response(status_code=204)

    async def http_error(request, exc):
        kind = {404: "NotFound", 405: "MethodNotAllowed"}.get(exc.status_code, "BadRequest")
        msg = exc.detail if isinstance(exc.detail, str) else "bad request"
        return failed(EditorError(f"{request.method} {request.url.path[:200]}: {msg}",
                                  status=exc.status_code, kind=kind))

    async def internal(request, exc):
        return failed(exc)

    routes = [
        Route("/", index),
        Route("/favicon.ico", no_favicon),
        Route("/api/run/{run}", run_status, methods=["GET"]),
        Route("/api/run/{run}/cancel", run_cancel, methods=["POST"]),
        Route("/api/run/{run}/signal", run_signal, methods=["GET"]),
        Route("/api/run/{run}/file/{name}", run_file, methods=["GET"]),
        Route("/api/live/stop", live_stop, methods=["POST"]),
        Route("/api/{op}", get_op, methods=["GET"]),
        Route("/api/{op}", post_op, methods=["POST"]),
    ]
    if STATIC.is_dir():
        routes.append(Mount("/", app=StaticFiles(directory=STATIC), name="static"))
    app = Starlette(routes=routes, exception_handlers={HTTPException: http_error,
                                                       Exception: internal})
    return Guard(TokenGate(app, token), port=port, names=names)


def bounded_protocol():
    """uvicorn's h11 protocol with two limits it lacks: each request must
    arrive whole within :data:`REQUEST_TIMEOUT` seconds, and at most
    :data:`MAX_CONNECTIONS` connections are held (see both). Without them
    a client that connects and sends nothing, or sends its headers or its
    body a byte at a time, kept its socket (and the body read so far) for
    ever: 200 such connections were all still open after minutes, 50 slow
    8 MB bodies held 350 MB."""
    import h11
    from uvicorn.protocols.http.h11_impl import H11Protocol

    class BoundedH11Protocol(H11Protocol):
        _deadline = None
        _since = 0.0

        def connection_made(self, transport):
            super().connection_made(transport)
            self._arm()
            if len(self.connections) > MAX_CONNECTIONS:
                waiting = [c for c in self.connections
                           if c is not self and getattr(c, "waiting", lambda: False)()]
                victim = min(waiting, key=lambda c: c._since) if waiting else self
                victim.cut()

        def waiting(self) -> bool:
            """Whether the connection waits for its client (a request not
            yet whole), not for the editor's answer."""
            return (not self.transport.is_closing()
                    and self.conn.their_state in (h11.IDLE, h11.SEND_BODY))

        def cut(self):
            self._disarm()
            if not self.transport.is_closing():
                self.transport.close()

        def _arm(self):
            self._disarm()
            self._since = self.loop.time()
            self._deadline = self.loop.call_later(REQUEST_TIMEOUT, self._expire)

        def _disarm(self):
            if self._deadline is not None:
                self._deadline.cancel()
                self._deadline = None

        def _expire(self):
            self._deadline = None
            if self.waiting():
                self.cut()

        def handle_events(self):
            super().handle_events()
            if self.conn.their_state is not h11.IDLE and not self.waiting():
                self._disarm()                  # the request is whole: answering

        def on_response_complete(self):
            super().on_response_complete()
            if not self.transport.is_closing():
                self._arm()                     # the next request, if any

        def handle_websocket_upgrade(self, event):
            self._disarm()                      # (the guard closes it anyway)
            super().handle_websocket_upgrade(event)

        def connection_lost(self, exc):
            self._disarm()
            super().connection_lost(exc)

    return BoundedH11Protocol


class EditorServer:
    """The editor served by uvicorn in a background thread.

    Parameters
    ----------
    service : EditorService
        What the API answers with.
    port : int
        Port on 127.0.0.1 (0: a free one).
    token : str, optional
        The URL token (default: random).

    Attributes
    ----------
    url : str
        ``http://127.0.0.1:PORT/<token>/`` once started.
    """

    def __init__(self, service: EditorService, port=0, token=None, host="127.0.0.1"):
        _imports()
        self.service = service
        self.token = make_token(token, EditorServerError)
        self.host = host
        self.port = int(port)
        self.url = None
        self._server = None
        self._thread = None

    def start(self, timeout=10.0) -> EditorServer:
        """Bind, serve in a background thread, return once it answers."""
        import uvicorn
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((self.host, self.port))
        except OSError as e:
            sock.close()
            raise EditorServerError(f"cannot listen on {self.host}:{self.port}: "
                                    f"{e.strerror or e}",
                                    hint="choose another --port, or leave it out for a "
                                         "free one") from None
        self.port = sock.getsockname()[1]
        names = () if self.host in ("127.0.0.1", "::1", "localhost") else (self.host,)
        # h11 always (not httptools where it is installed): its header limit
        # and the request deadline and connection cap of bounded_protocol
        config = uvicorn.Config(make_app(self.service, self.token, port=self.port,
                                         names=names),
                                log_level="warning", access_log=False, lifespan="off",
                                http=bounded_protocol(),
                                h11_max_incomplete_event_size=64 * 1024)
        self._server = uvicorn.Server(config)
        self._server.install_signal_handlers = lambda: None   # uvicorn < 0.29
        self._thread = threading.Thread(target=self._serve, args=(sock,), daemon=True,
                                        name="avblocks-editor")
        self._thread.start()
        import time
        t_end = time.monotonic() + timeout
        while not self._server.started:
            if not self._thread.is_alive() or time.monotonic() > t_end:
                raise EditorServerError("the editor's server did not start")
            time.sleep(0.01)
        self.url = f"http://{self.host}:{self.port}/{self.token}/"
        return self

    def _serve(self, sock):
        # uvicorn.Server.run installs signal handlers only in the main thread
        asyncio.run(self._server.serve(sockets=[sock]))

    def stop(self, timeout=5.0):
        """Stop serving and end the runs."""
        if self._server is not None:
            self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout)
        self.service.close()

    def __enter__(self):
        return self.start() if self.url is None else self

    def __exit__(self, *exc):
        self.stop()
