"""The editor's HTTP server: a small Starlette app on 127.0.0.1 behind a token.

The page is served at ``http://127.0.0.1:PORT/<token>/`` (the token is a
random URL-safe string, as the live view's): every request whose first path
segment is not the token gets ``403`` before anything else looks at it. Under
the token:

* ``/`` and ``/assets/...``: the built front end (``editor/static/``);
* ``GET api/palette``, ``GET api/files``: the catalogue and the files;
* ``POST api/<op>`` with a JSON body: ``load``, ``validate``, ``save``,
  ``run``, ``live``, ``export``;
* ``GET api/run/<run>``, ``POST api/run/<run>/cancel``,
  ``GET api/run/<run>/signal?name=...``, ``GET api/run/<run>/file/<name>``.

The operations are those of :class:`~avblocks.editor.service.EditorService`
(see ``API.md``); errors come back as ``{"error": {"message", "kind"}}``
with a 4xx status. :class:`EditorServer` runs uvicorn in a background
thread.
"""

from __future__ import annotations

import asyncio
import json
import socket
import threading
from pathlib import Path

from ..core.errors import AvError
from ..core.urltoken import make_token, under_token
from .service import EditorError, EditorService, error_json

#: Where the built front end lies (``index.html``, ``assets/``, ``widget.js``).
STATIC = Path(__file__).parent / "static"
#: Request bodies larger than this are refused (413).
MAX_BODY = 8 * 1024 * 1024


class EditorServerError(AvError):
    """The editor could not start (missing extra, port taken...)."""


def _imports():
    try:
        import starlette  # noqa: F401
        import uvicorn  # noqa: F401
    except ImportError as e:
        raise EditorServerError(f"the editor needs starlette and uvicorn ({e})",
                                hint='pip install "avblocks[editor]"') from None


class _TokenGate:
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
            body = b"avblocks editor: wrong or missing token\n"
            await send({"type": "http.response.start", "status": 403,
                        "headers": [(b"content-type", b"text/plain; charset=utf-8"),
                                    (b"content-length", str(len(body)).encode())]})
            await send({"type": "http.response.body", "body": body})
            return
        if after == b"":          # /<token> -> /<token>/ so relative URLs work
            loc = self.prefix + b"/"
            await send({"type": "http.response.start", "status": 307,
                        "headers": [(b"location", loc), (b"content-length", b"0")]})
            await send({"type": "http.response.body", "body": b""})
            return
        scope = dict(scope)
        scope["path"] = scope["path"][len(self.prefix):]
        scope["raw_path"] = after
        scope["root_path"] = scope.get("root_path", "") + self.prefix.decode()
        return await self.app(scope, receive, send)


def make_app(service: EditorService, token: str):
    """The ASGI app (token gate included) serving ``service``."""
    _imports()
    from starlette.applications import Starlette
    from starlette.responses import FileResponse, HTMLResponse, JSONResponse, Response
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    async def call(fn, *a, **kw):
        try:
            result = await asyncio.to_thread(fn, *a, **kw)
        except (AvError, Exception) as e:  # noqa: BLE001 - every failure as JSON
            status, body = error_json(e)
            return JSONResponse(body, status_code=status)
        if isinstance(result, Path):
            return FileResponse(result)
        return JSONResponse(result)

    async def body_of(request):
        if int(request.headers.get("content-length") or 0) > MAX_BODY:
            raise EditorError("request too large", status=413, kind="TooLarge")
        raw = await request.body()
        if len(raw) > MAX_BODY:
            raise EditorError("request too large", status=413, kind="TooLarge")
        if not raw:
            return {}
        try:
            data = json.loads(raw)
        except ValueError as e:
            raise EditorError(f"the body is not JSON: {e}", kind="BadRequest") from None
        if not isinstance(data, dict):
            raise EditorError("the body is a JSON object of arguments", kind="BadRequest")
        return data

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
            return JSONResponse({"error": {"message": f"GET {op}: use POST",
                                           "kind": "BadRequest"}}, status_code=405)
        return await call(service.call, op, {})

    async def post_op(request):
        try:
            args = await body_of(request)
        except EditorError as e:
            status, body = error_json(e)
            return JSONResponse(body, status_code=status)
        return await call(service.call, request.path_params["op"], args)

    async def run_status(request):
        return await call(service.status, request.path_params["run"])

    async def run_cancel(request):
        return await call(service.cancel, request.path_params["run"])

    async def run_signal(request):
        return await call(service.signal, request.path_params["run"],
                          request.query_params.get("name"))

    async def run_file(request):
        return await call(service.figure, request.path_params["run"],
                          request.path_params["name"])

    async def no_favicon(request):
        return Response(status_code=204)

    routes = [
        Route("/", index),
        Route("/favicon.ico", no_favicon),
        Route("/api/run/{run}", run_status, methods=["GET"]),
        Route("/api/run/{run}/cancel", run_cancel, methods=["POST"]),
        Route("/api/run/{run}/signal", run_signal, methods=["GET"]),
        Route("/api/run/{run}/file/{name}", run_file, methods=["GET"]),
        Route("/api/{op}", get_op, methods=["GET"]),
        Route("/api/{op}", post_op, methods=["POST"]),
    ]
    if STATIC.is_dir():
        routes.append(Mount("/", app=StaticFiles(directory=STATIC), name="static"))
    app = Starlette(routes=routes)
    return _TokenGate(app, token)


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
        config = uvicorn.Config(make_app(self.service, self.token), log_level="warning",
                                access_log=False, lifespan="off")
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
