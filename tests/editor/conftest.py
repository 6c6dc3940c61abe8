"""Fixtures for the editor's tests: a real server on loopback.

``editor_server`` starts :class:`~avblocks.editor.server.EditorServer` in this
process (uvicorn in a background thread, a free port on 127.0.0.1) serving a
fresh temporary folder, and yields an :class:`EditorHandle` with ``url``
(``http://127.0.0.1:PORT/<token>/``), ``base`` (the same without the token),
``token``, ``root`` (the folder) and small HTTP helpers. The browser tests
reuse it.
"""

from __future__ import annotations

import json
import os
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import pytest


def _need(*modules):
    import importlib.util
    missing = [m for m in modules if importlib.util.find_spec(m) is None]
    if missing:
        if os.environ.get("CI"):
            pytest.fail(f"the editor tests need {missing} in CI")
        pytest.skip(f"needs {missing} (pip install 'avblocks[editor]')")


@pytest.fixture
def need_editor_extra():
    """``need("module", ...)``: skip without them (fail in CI)."""
    return _need


@dataclass
class EditorHandle:
    url: str
    base: str
    token: str
    root: Path
    server: object

    def request(self, method, op, body=None, *, url=None, timeout=60):
        """``(status, decoded JSON or bytes)`` of one request to ``api/<op>``."""
        target = url or self.url + "api/" + op
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(target, data=data, method=method,
                                     headers={"content-type": "application/json"})
        try:
            with urllib.request.urlopen(req, timeout=timeout) as r:
                status, raw, ctype = r.status, r.read(), r.headers.get("content-type", "")
        except urllib.error.HTTPError as e:
            status, raw, ctype = e.code, e.read(), e.headers.get("content-type", "")
        return status, (json.loads(raw) if "json" in ctype else raw)

    def get(self, op, **kw):
        return self.request("GET", op, **kw)

    def post(self, op, body=None, **kw):
        return self.request("POST", op, body if body is not None else {}, **kw)


@pytest.fixture
def editor_server(tmp_path):
    """A running editor on a free loopback port serving ``tmp_path``."""
    _need("starlette", "uvicorn")
    from avblocks.editor.server import EditorServer
    from avblocks.editor.service import EditorService
    srv = EditorServer(EditorService(tmp_path)).start()
    try:
        yield EditorHandle(url=srv.url, base=f"http://127.0.0.1:{srv.port}/",
                           token=srv.token, root=tmp_path, server=srv)
    finally:
        srv.stop()
