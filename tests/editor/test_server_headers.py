"""Who may talk to the editor's server, and what every answer carries.

Requests are made with ``http.client`` over loopback with the headers a
browser would send (a DNS-rebinding page: ``Host: evil.example``; a page
on another origin: ``Origin: http://evil.example``, ``text/plain``), and
the page itself is loaded in the system Chromium, which enforces the
Content-Security-Policy: truth is the browser's own report of violations.
"""

from __future__ import annotations

import http.client
import json
import os
from html.parser import HTMLParser
from pathlib import Path

import pytest

STATIC = Path(__file__).resolve().parents[2] / "src" / "avblocks" / "editor" / "static"
CHROMIUM = "/usr/bin/chromium"
MUST = {"content-security-policy", "referrer-policy", "x-content-type-options"}


def _port(srv):
    return int(srv.base.rsplit(":", 1)[1].strip("/"))


def _raw(srv, method, path, *, host=None, headers=(), body=None, announce=None):
    """``(status, headers as a dict, body bytes)`` of one request with the
    ``Host`` given (None: the usual ``127.0.0.1:PORT``)."""
    conn = http.client.HTTPConnection("127.0.0.1", _port(srv), timeout=30)
    conn.putrequest(method, path, skip_host=True, skip_accept_encoding=True)
    conn.putheader("Host", host if host is not None else f"127.0.0.1:{_port(srv)}")
    for k, v in headers:
        conn.putheader(k, v)
    data = body if body is not None else b""
    if method == "POST":
        conn.putheader("Content-Length", str(announce or len(data)))
    conn.endheaders(data if method == "POST" else None)
    r = conn.getresponse()
    out = r.status, {k.lower(): v for k, v in r.getheaders()}, r.read()
    conn.close()
    return out


def _secured(headers):
    assert MUST <= set(headers), sorted(headers)
    csp = headers["content-security-policy"]
    for part in ("default-src 'self'", "script-src 'self'", "connect-src 'self'",
                 "frame-ancestors 'none'", "object-src 'none'"):
        assert part in csp, csp
    assert "unsafe-inline" not in csp and "unsafe-eval" not in csp
    assert headers["referrer-policy"] == "no-referrer"
    assert headers["x-content-type-options"] == "nosniff"


def test_only_loopback_host_names_with_the_port_are_served(editor_server):
    srv = editor_server
    port = _port(srv)
    path = f"/{srv.token}/api/files"
    for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"[::1]:{port}",
                 f"LOCALHOST:{port}"):
        status, headers, _ = _raw(srv, "GET", path, host=host)
        assert status == 200, host
        _secured(headers)
    for host in ("evil.example", f"evil.example:{port}", f"127.0.0.1:{port + 1}",
                 "127.0.0.1", f"127.0.0.2:{port}", f"localhost.evil.example:{port}", ""):
        status, headers, body = _raw(srv, "GET", path, host=host)
        assert status == 400, host
        assert json.loads(body)["error"]["kind"] == "BadHost"
        _secured(headers)


def test_a_cross_origin_post_is_refused_and_writes_nothing(editor_server):
    srv = editor_server
    port = _port(srv)
    save = f"/{srv.token}/api/save"
    doc = json.dumps({"path": "x.yaml", "document": {"name": "x"}, "draft": True}).encode()
    # what a page on another origin can send without asking (a "simple" request)
    for origin in ("http://evil.example", "null", f"http://127.0.0.1:{port + 1}",
                   f"https://127.0.0.1:{port}", "http://localhost"):
        for ctype in ("text/plain", "application/json"):
            status, headers, body = _raw(srv, "POST", save, body=doc,
                                         headers=[("Origin", origin),
                                                  ("Content-Type", ctype)])
            assert status == 403, (origin, ctype)
            assert json.loads(body)["error"]["kind"] == "CrossOrigin"
            _secured(headers)
    # a page's fetch from another site that sends no Origin but Sec-Fetch-*
    status, _, body = _raw(srv, "POST", save, body=doc,
                           headers=[("Sec-Fetch-Site", "cross-site"),
                                    ("Sec-Fetch-Mode", "no-cors"),
                                    ("Content-Type", "text/plain")])
    assert status == 403
    # text/plain without an Origin (a script, not a browser) is still not JSON
    status, _, body = _raw(srv, "POST", save, body=doc,
                           headers=[("Content-Type", "text/plain")])
    assert status == 415 and json.loads(body)["error"]["kind"] == "UnsupportedMediaType"
    assert not list(srv.root.iterdir())
    # the page itself: same origin, JSON
    for origin in (f"http://127.0.0.1:{port}", f"http://localhost:{port}"):
        status, _, body = _raw(srv, "POST", save, body=doc,
                               headers=[("Origin", origin),
                                        ("Content-Type", "application/json")])
        assert status == 200, body
    assert (srv.root / "x.yaml").is_file()


def test_every_answer_carries_the_security_headers(editor_server):
    srv = editor_server
    t = srv.token
    cases = [
        ("GET", f"/{t}/", None, 200),                       # the page
        ("GET", f"/{t}/api/palette", None, 200),
        ("GET", f"/{t}/api/new", None, 200),
        ("GET", "/", None, 403),                            # the token gate
        ("GET", f"/{t}x/api/files", None, 403),
        ("GET", f"/{t}", None, 307),
        ("GET", f"/{t}/api/nope/deeper/still", None, 404),  # no such route: JSON
        ("GET", f"/{t}/api/run/abc", None, 404),
        ("GET", f"/{t}/api/run/abc/cancel", None, 404),     # (the page's mount)
        ("GET", f"/{t}/api/save", None, 405),
        ("POST", f"/{t}/api/files", b"{}", 405),
        ("POST", f"/{t}/api/validate", b"[", 400),
        ("POST", f"/{t}/api/validate", b"", 413),        # announced 9 MB: not read
    ]
    assets = sorted((STATIC / "assets").glob("*.js")) if (STATIC / "assets").is_dir() else []
    if assets:
        cases.append(("GET", f"/{t}/assets/{assets[0].name}", None, 200))
    for method, path, body, want in cases:
        headers = [("Content-Type", "application/json")] if body is not None else []
        status, got, raw = _raw(srv, method, path, body=body, headers=headers,
                                announce=9 * 1024 * 1024 if want == 413 else None)
        assert status == want, (method, path[:60], status, raw[:200])
        _secured(got)
        if status >= 400 and status != 403:
            assert "json" in got["content-type"], (path, got)
            assert set(json.loads(raw)["error"]) >= {"message", "kind"}


class _Inline(HTMLParser):
    """What of a page the CSP would block: inline scripts, inline styles,
    event-handler attributes, scripts or styles from elsewhere."""

    def __init__(self):
        super().__init__()
        self.found = []
        self._in = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        for k in a:
            if k.startswith("on") or k == "style":
                self.found.append(f"<{tag} {k}=>")
        if tag == "script":
            src = a.get("src")
            if src is None:
                self._in = "script"
            elif "//" in src or src.startswith("data:"):
                self.found.append(f"script from {src}")
        if tag == "style":
            self._in = "style"
        if tag == "link" and a.get("rel") == "stylesheet" and "//" in (a.get("href") or ""):
            self.found.append(f"stylesheet from {a['href']}")

    def handle_endtag(self, tag):
        self._in = None

    def handle_data(self, data):
        if self._in and data.strip():
            self.found.append(f"inline {self._in}: {data.strip()[:60]}")


def test_the_built_page_needs_no_inline_script_or_style():
    page = STATIC / "index.html"
    if not page.is_file():
        if os.environ.get("CI"):
            pytest.fail("the built front end is missing in CI")
        pytest.skip("the front end is not built")
    p = _Inline()
    p.feed(page.read_text())
    assert p.found == []


def test_the_page_runs_under_its_csp_in_a_real_browser(editor_server):
    """Chromium enforces the policy the server sends: the page loads, draws
    a case study (nodes, wires, the palette) and reports no violation."""
    missing = [m for m, ok in (("playwright", _has_playwright()),
                               (CHROMIUM, Path(CHROMIUM).exists()),
                               ("editor/static", (STATIC / "index.html").is_file())) if not ok]
    if missing:
        if os.environ.get("CI"):
            pytest.fail(f"needs {missing} in CI")
        pytest.skip(f"needs {missing}")
    from playwright.sync_api import sync_playwright
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM,
                               args=["--headless", "--no-sandbox", "--disable-gpu"])
        try:
            pg = b.new_page(viewport={"width": 1440, "height": 880}, accept_downloads=True)
            pg.add_init_script("window.__csp = []; document.addEventListener("
                               "'securitypolicyviolation', e => window.__csp.push("
                               "e.violatedDirective + ' ' + e.blockedURI));")
            console = []
            pg.on("console", lambda m: console.append(m.text) if m.type == "error" else None)
            # the page opens a case study first (as `avblocks edit formation`)
            editor_server.server.service.initial = {"builtin": "formation"}
            r = pg.goto(editor_server.url)
            assert r.headers["content-security-policy"].startswith("default-src 'self'")
            pg.wait_for_selector(".palette-item", timeout=60_000)
            pg.wait_for_selector(".react-flow__node", timeout=60_000)
            pg.wait_for_selector(".react-flow__edge", timeout=60_000)
            nodes = pg.locator(".react-flow__node").count()
            # a run: its figures are images from the server, its signals a plot
            pg.get_by_label("t_final").fill("2")
            pg.get_by_test_id("run").click()
            pg.locator(".run-state.done").wait_for(timeout=120_000)
            pg.locator('.av-wire-label[data-wire="fleet.pose->drive.pose"]').click(force=True)
            pg.get_by_test_id("signal-plot").wait_for(timeout=30_000)
            shown = pg.locator("img").evaluate_all(
                "imgs => imgs.filter(i => i.complete && i.naturalWidth > 0).length")
            # an export is a download of a data: URL
            with pg.expect_download() as dl:
                pg.get_by_label("Export").select_option("svg")
            exported = Path(dl.value.path()).read_bytes()
            pg.wait_for_timeout(300)
            violations = pg.evaluate("window.__csp")
        finally:
            b.close()
    assert nodes >= 3                        # formation's blocks are drawn
    assert shown >= 1                        # the run's figure was shown
    assert b"<svg" in exported
    assert violations == [], violations
    assert not [c for c in console if "Content Security Policy" in c], console


def _has_playwright():
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return False
    return True
