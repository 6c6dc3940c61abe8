"""The editor's limits on a real server: JSON depth and size checked before
parsing, every argument typed, live views bounded and stopped.

Truth: the status and JSON body the server answers (against the documented
ones of ``API.md``), and for live views the kernel's own count of this
process's listening sockets (``/proc/net/tcp*`` joined with
``/proc/self/fd``) and threads (``/proc/self/status``).
"""

from __future__ import annotations

import http.client
import json
import os
from pathlib import Path

import pytest

from avblocks.editor.service import OPERATIONS

DOC = {"name": "tiny", "parameters": {"agents": 3, "seed": 1},
       "blocks": {"fleet": {"type": "vehicles.Unicycle",
                            "pose0": {"random_poses": {"n": "$agents", "area": [10, 10],
                                                       "seed": "$seed"}}},
                  "drive": {"type": "controllers.PointToPoint", "n": "$agents",
                            "waypoints": {"random_waypoints": {"n": "$agents", "count": 2,
                                                               "area": [10, 10],
                                                               "seed": "$seed"}}}},
       "wires": [["fleet.pose", "drive.pose"], ["drive.cmd", "fleet.cmd"]],
       "simulation": {"t_final": 30, "dt": 0.05}}


def _post_raw(srv, op, raw: bytes):
    port = int(srv.base.rsplit(":", 1)[1].strip("/"))
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    conn.request("POST", f"/{srv.token}/api/{op}", body=raw,
                 headers={"content-type": "application/json"})
    r = conn.getresponse()
    status, ctype, body = r.status, r.getheader("content-type", ""), r.read()
    conn.close()
    assert "json" in ctype, (status, body[:300])
    return status, json.loads(body)


@pytest.mark.parametrize("depth", [101, 500, 990, 5000, 100_000])
@pytest.mark.parametrize("op", ["validate", "save", "run", "export"])
def test_deep_json_is_a_400_before_it_is_parsed(editor_server, op, depth):
    """Before: depth 500 was a JSON ``InternalError``, ~990 and more a
    plain-text 500 with a traceback in the log."""
    deep = "[" * depth + "]" * depth
    raw = ('{"path": "x.yaml", "document": {"name": "x", "blocks": {"a": {"type": '
           '"vehicles.Unicycle", "pose0": ' + deep + '}}}}').encode()
    status, body = _post_raw(editor_server, op, raw)
    assert status == 400, body
    assert body["error"]["kind"] == "BadRequest" and "deeper than 100" in \
        body["error"]["message"]


@pytest.mark.parametrize("encoding", ["utf-16-le", "utf-16", "utf-32-le", "utf-8-sig"])
@pytest.mark.parametrize("op", ["validate", "save", "export"])
def test_a_body_in_another_encoding_is_a_400_and_cannot_hide_its_depth(editor_server, op,
                                                                       encoding):
    """JSON travels as UTF-8 (RFC 8259, section 8.1). ``json.loads`` of
    bytes also reads UTF-16 and UTF-32, where an escaped quote (``\\"``)
    threw the depth scan out of step with the parser: a document nested
    900 deep in UTF-16 reached the service and was a 500 ``RecursionError``
    (attack42). Any body that is not UTF-8 text is now a 400, and so is a
    byte-order mark."""
    deep = "[" * 900 + "]" * 900
    text = ('{"path": "a\\"b.yaml", "document": {"blocks": {"a": {"type": '
            '"vehicles.Unicycle", "pose0": ' + deep + '}}, "name": "x"}}')
    status, body = _post_raw(editor_server, op, text.encode(encoding))
    assert status == 400 and body["error"]["kind"] == "BadRequest", body
    small = json.dumps({"document": DOC}).encode(encoding)
    status, body = _post_raw(editor_server, op, small)
    assert status == 400 and body["error"]["kind"] == "BadRequest", body


def _still_open(sock) -> bool:
    """Whether the server still holds ``sock``'s connection (no end of file,
    no reset)."""
    sock.setblocking(False)
    try:
        return sock.recv(1 << 16) != b""
    except BlockingIOError:
        return True
    except OSError:
        return False


def test_idle_and_slow_clients_are_cut_off_and_others_are_served(editor_server,
                                                                 monkeypatch):
    """A client that connects and sends nothing, or its headers or body a
    byte at a time, held its connection (and the body read so far) for
    ever: 200 such sockets were all open after minutes, 50 slow 8 MB bodies
    held 350 MB (attack42). Now a request must arrive whole within
    REQUEST_TIMEOUT, at most MAX_CONNECTIONS are held (a new one cuts off
    the oldest still sending), and the page's own requests are answered
    meanwhile. Truth: the server's side of each socket, seen as end of
    file or reset by the client."""
    import socket
    import time

    import avblocks.editor.server as srv
    monkeypatch.setattr(srv, "REQUEST_TIMEOUT", 1.5)
    monkeypatch.setattr(srv, "MAX_CONNECTIONS", 16)
    port = int(editor_server.base.rsplit(":", 1)[1].strip("/"))
    host = f"127.0.0.1:{port}"
    socks = []
    for i in range(45):
        s = socket.create_connection(("127.0.0.1", port), timeout=5)
        if i % 3 == 1:                                   # headers, never finished
            s.sendall(f"GET /{editor_server.token}/api/new HTTP/1.1\r\nHost: {host}\r\n"
                      "X-Slow: a".encode())
        elif i % 3 == 2:                                 # a body, never finished
            s.sendall(f"POST /{editor_server.token}/api/validate HTTP/1.1\r\nHost: {host}"
                      "\r\nContent-Type: application/json\r\nContent-Length: 1000000"
                      "\r\n\r\n{\"document\": ".encode())
        socks.append(s)
    time.sleep(0.3)
    status, body = editor_server.get("new")              # the page is still served
    assert status == 200 and body["document"]["blocks"] == {}
    assert sum(_still_open(s) for s in socks) <= 16
    time.sleep(2.5)                                      # past the deadline
    assert sum(_still_open(s) for s in socks) == 0
    status, body = editor_server.post("validate", {"document": DOC})
    assert status == 200 and body["ok"], body
    for s in socks:
        s.close()


def test_json_within_the_depth_limit_is_answered(editor_server):
    deep = {"x": 1}
    for _ in range(90):
        deep = {"x": deep}
    doc = dict(DOC, blocks={**DOC["blocks"], "fleet": {**DOC["blocks"]["fleet"],
                                                        "v_max": deep}})
    status, body = editor_server.post("validate", {"document": doc})
    assert status == 200 and not body["ok"]
    assert body["errors"][0]["block"] == "fleet", body["errors"]


def test_too_many_values_and_huge_numbers_are_400(editor_server):
    for raw in (b'{"document": {"x": [' + b"0," * 1_100_000 + b'0]}}',
                b'{"document": {"x": ' + b"9" * 5000 + b"}}",
                b'{"document": {"x": "\xff\xfe"}}', b"[1, 2]", b'"text"'):
        status, body = _post_raw(editor_server, "validate", raw)
        assert status == 400 and body["error"]["kind"] == "BadRequest", (raw[:40], body)


@pytest.mark.parametrize("value", [b"NaN", b"Infinity", b"-Infinity"])
def test_nan_and_infinity_reach_the_library_which_names_the_field(editor_server, value):
    """A field where `.nan` or `1e999` is typed sends that number (the page
    writes it as Python's json does); the library's own message comes back
    on that parameter, and a draft holding it reads back with the number."""
    doc = json.dumps(dict(DOC, blocks={**DOC["blocks"], "drive": {
        **DOC["blocks"]["drive"], "v_max": "@V@"}})).encode().replace(b'"@V@"', value)
    status, body = _post_raw(editor_server, "validate", b'{"document": ' + doc + b"}")
    assert status == 200 and not body["ok"], body
    on_field = [e for e in body["errors"] if e["block"] == "drive" and e["param"] == "v_max"]
    assert on_field and "finite" in on_field[0]["message"], body["errors"]
    status, body = _post_raw(editor_server, "save", b'{"path": "d.yaml", "draft": true, '
                             b'"document": ' + doc + b"}")
    assert status == 200 and body["draft"] is True, body
    status, body = _post_raw(editor_server, "load", b'{"path": "d.yaml"}')
    assert status == 200, body
    v = body["document"]["blocks"]["drive"]["v_max"]
    assert v != v if value == b"NaN" else v == float(value.decode()), v


def test_booleans_and_names_are_checked_by_type(editor_server):
    """Before: ``draft: "yes"`` and ``create: "no"`` read as true, a name
    ``5`` or ``["a"]`` passed validation."""
    srv = editor_server
    for extra in ({"draft": "yes"}, {"draft": 1}, {"create": "no"}, {"create": []},
                  {"revision": 5}, {"origin": ["a"]}):
        status, body = srv.post("save", {"path": "x.yaml", "document": DOC, **extra})
        assert status == 400 and body["error"]["kind"] == "BadRequest", (extra, body)
        assert next(iter(extra)) in body["error"]["message"]
    assert not (srv.root / "x.yaml").exists()
    for name in (5, ["a"], {"a": 1}, True, 1.5):
        for op in ("validate", "save", "run", "export"):
            extra = {"draft": True} if op == "save" else {}
            status, body = srv.post(op, {"document": {**DOC, "name": name},
                                         "path": "x.yaml", **extra})
            assert status == 400 and body["error"]["kind"] == "BadDocument", (op, name, body)
    status, body = srv.post("save", {"path": "x.yaml", "document": DOC, "draft": False,
                                     "create": True})
    assert status == 200, body                      # real booleans still work


def test_the_argument_table_is_each_operations_signature():
    """The table that types the arguments names exactly the parameters of
    each operation's method (an argument added to a method and not to the
    table was refused as unknown: the Tune tab's ``figures`` was)."""
    import inspect

    from avblocks.editor.service import EditorService
    for op, spec in OPERATIONS.items():
        params = inspect.signature(getattr(EditorService, op)).parameters
        assert set(spec) == set(params) - {"self"}, op
        for name, p in params.items():
            if name != "self":
                assert spec[name].required == (p.default is inspect.Parameter.empty), (op, name)


SAMPLES = {"text": "a.yaml", "bool": True, "number": 1.5, "mapping": {"name": "x"}}
WRONG = [None, True, 0, -1.5, "", "x", [], ["a"], {}, {"a": 1}]


@pytest.mark.parametrize("op", sorted(OPERATIONS))
def test_every_argument_of_every_operation_is_typed(editor_server, op):
    """Each argument of :data:`OPERATIONS` given a value of every other JSON
    type: a 400 ``BadRequest`` (``BadDocument`` for a document) naming it;
    an unknown argument: a 400 naming it."""
    srv = editor_server
    spec = OPERATIONS[op]
    base = {k: SAMPLES[a.kind] for k, a in spec.items() if a.required}
    if op in ("palette", "files", "new"):
        status, body = srv.post(op, {})
        assert status == 405 and body["error"]["kind"] == "MethodNotAllowed"
        return
    route = {"status": None, "cancel": "run/x/cancel", "signal": None,
             "live_stop": "live/stop"}.get(op, op)
    if route is None:                  # GET routes: the service takes them
        from avblocks.editor.service import EditorService
        svc = EditorService(srv.root)
        try:
            for k, a in spec.items():
                for v in WRONG:
                    if v is None and not a.required or _fits(a.kind, v):
                        continue
                    with pytest.raises(Exception) as e:
                        svc.call(op, {**base, k: v})
                    assert getattr(e.value, "status", None) == 400 and k in str(e.value)
        finally:
            svc.close()
        return
    if route != op:
        base.pop("run", None)          # given by the URL
    for k, a in spec.items():
        if route != op and k == "run":
            continue                   # given by the URL
        for v in WRONG:
            if (v is None and not a.required) or _fits(a.kind, v):
                continue
            status, body = srv.post(route, {**base, k: v})
            assert status == 400, (op, k, v, body)
            assert body["error"]["kind"] == ("BadDocument" if k == "document"
                                             else "BadRequest"), body
            assert k in body["error"]["message"], body
    status, body = srv.post(route, {**base, "evil": 1})
    assert status == 400 and "evil" in body["error"]["message"]


def _fits(kind, v):
    return {"text": isinstance(v, str), "bool": isinstance(v, bool),
            "number": isinstance(v, (int, float)) and not isinstance(v, bool),
            "mapping": isinstance(v, dict)}[kind]


def _listening() -> int:
    """Listening TCP sockets this process holds (kernel tables)."""
    inodes = set()
    for f in ("/proc/net/tcp", "/proc/net/tcp6"):
        if Path(f).exists():
            for line in Path(f).read_text().splitlines()[1:]:
                cols = line.split()
                if cols[3] == "0A":                     # TCP_LISTEN
                    inodes.add(cols[9])
    mine = 0
    for fd in os.listdir("/proc/self/fd"):
        try:
            link = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue
        if link.startswith("socket:[") and link[8:-1] in inodes:
            mine += 1
    return mine


def _threads() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("Threads:"):
            return int(line.split()[1])
    raise AssertionError("no Threads line")


def test_29_live_views_leave_at_most_two_listening(editor_server, need_editor_extra):
    """Before: 29 ``POST live`` left 30 listening sockets and 64 threads."""
    need_editor_extra("viser")
    if not Path("/proc/net/tcp").exists():
        if os.environ.get("CI"):
            pytest.fail("reads /proc (Linux CI)")
        pytest.skip("counts sockets in /proc (Linux)")
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from avblocks.editor.lives import MAX_LIVE
    srv = editor_server
    with ThreadPoolExecutor(32) as pool:       # the server's worker threads all started
        assert {s for s, _ in pool.map(lambda _: srv.get("new"), range(64))} == {200}
    sockets0, threads0 = _listening(), _threads()
    status, first = srv.post("live", {"document": DOC})
    assert status == 200, first
    per_view = _threads() - threads0
    urls = [first["url"]]
    for _ in range(28):
        status, body = srv.post("live", {"document": DOC})
        assert status == 200, body
        urls.append(body["url"])
    sockets, threads = _listening(), _threads()
    print(f"\n29 live views: {sockets - sockets0} listening sockets, "
          f"{threads - threads0} threads more than before ({per_view} for one view)")
    assert len(set(urls)) == 29
    assert sockets - sockets0 <= MAX_LIVE
    assert threads - threads0 <= MAX_LIVE * per_view + 2
    assert sum(t.name == "avblocks-live" for t in threading.enumerate()) <= MAX_LIVE
    # the two newest answer, the oldest does not
    import urllib.error
    import urllib.request
    with urllib.request.urlopen(urls[-1], timeout=30) as r:
        assert r.status == 200
    with pytest.raises(urllib.error.URLError):
        urllib.request.urlopen(urls[0], timeout=5)
    # the page stops one, then all
    status, body = srv.post("live/stop", {"url": urls[-1]})
    assert status == 200 and body["stopped"] == [urls[-1]]
    status, body = srv.post("live/stop", {"url": urls[-1]})
    assert status == 404 and body["error"]["kind"] == "NotFound"
    status, body = srv.post("live/stop", {})
    assert status == 200 and body["stopped"] == [urls[-2]]
    assert _listening() == sockets0
    assert _threads() <= threads0 + 2
    assert not [t for t in threading.enumerate() if t.name == "avblocks-live"]
