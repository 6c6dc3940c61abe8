"""Fuzzing the editor's HTTP API (hypothesis) against a real ``avblocks
edit`` process, the way an attacker on the machine or a hostile web page
would try it.

Every operation of ``API.md`` is called with arguments of every JSON type
(documents mutated from a valid one, values nested deep, unknown keys,
required ones left out) and with hostile paths (unicode, NUL, ``..``,
absolute, very long, deep, symbolic links out of the folder, Windows
forms); hand-written cases add what hypothesis would rarely reach (deep
nesting past the limit, huge and chunked bodies, NUL and long names, the
routes' odd URLs). Each answer must be one the API documents: a 200 with
JSON, or a 4xx with ``{"error": {"message", "kind"}}`` and a documented
kind; never a 500. Afterwards nothing may exist outside the folder that was
not there before, no ``.part`` file may be left in it, and the server's
resident memory (``/proc/PID/status``) may not have grown by more than
300 MB.

The table of operations and their arguments is written here from
``API.md``, not imported from the server. Examples are fixed in number and
derandomized: the fast profile (every CI run) makes 600 calls, then about
170 hand-written and concurrent ones, in about 20 s with the server's
start; the ``slow`` one 2,000 more calls (about 50 s).

``AVBLOCKS_FUZZ_TALLY=FILE`` records every answer instead of failing and
writes ``{"tried", "clean", "ok", "500", "other"}`` to FILE: how the fuzz
counts of issue 42 were measured on the code before and after.
"""

from __future__ import annotations

import http.client
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

SRC = Path(__file__).resolve().parents[2] / "src"
TALLY = os.environ.get("AVBLOCKS_FUZZ_TALLY")
FAST = settings(max_examples=600, deadline=None, database=None, derandomize=True,
                suppress_health_check=list(HealthCheck))
LONG = settings(max_examples=2000, deadline=None, database=None, derandomize=True,
                suppress_health_check=list(HealthCheck))

# ------------------------------------------------------------ what API.md says
STATUSES = {200, 400, 404, 405, 409, 413, 415}
EDITOR_KINDS = {"BadRequest", "BadDocument", "BadPath", "OutsideFolder", "NotFound",
                "NotEditable", "InvalidDiagram", "MissingExtra", "Busy", "Conflict",
                "Exists", "TooLarge", "UnsupportedMediaType", "MethodNotAllowed",
                "ScenarioError", "FileError", "FileTooLarge", "BadHost", "CrossOrigin"}


def _library_kinds():
    import avblocks.editor  # noqa: F401 - every error class defined
    import avblocks.scenarios.loader  # noqa: F401
    from avblocks.core.errors import AvError
    seen, todo = set(), [AvError]
    while todo:
        c = todo.pop()
        seen.add(c.__name__)
        todo.extend(c.__subclasses__())
    return seen - {"EditorError"}


KINDS = EDITOR_KINDS | _library_kinds()

DOC = {"name": "tiny", "parameters": {"agents": 3, "seed": 1},
       "blocks": {"fleet": {"type": "vehicles.Unicycle",
                            "pose0": {"random_poses": {"n": "$agents", "area": [10, 10],
                                                       "seed": "$seed"}}},
                  "drive": {"type": "controllers.PointToPoint", "n": "$agents",
                            "waypoints": {"random_waypoints": {"n": "$agents", "count": 2,
                                                               "area": [10, 10],
                                                               "seed": "$seed"}}}},
       "wires": [["fleet.pose", "drive.pose"], ["drive.cmd", "fleet.cmd"]],
       "simulation": {"t_final": 1, "dt": 0.05},
       "editor": {"layout": {"fleet": [0, 0], "drive": [200, 0]}}}

# operation -> its arguments (from API.md)
OPS = {
    "load": ("path", "builtin"),
    "validate": ("document", "path"),
    "save": ("path", "document", "revision", "draft", "origin", "create"),
    "run": ("document", "backend", "t_final", "dt", "path"),
    "live": ("document", "path"),
    "export": ("document", "format", "path"),
}
GETS = ("palette", "files", "new")

# --------------------------------------------------------------- strategies
scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**30, 10**30),
                    st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=20))
json_values = st.recursive(scalars, lambda ch: st.lists(ch, max_size=4)
                           | st.dictionaries(st.text(max_size=8), ch, max_size=4),
                           max_leaves=12)


def nested(depth, leaf=0):
    v = leaf
    for i in range(depth):
        v = [v] if i % 2 else {"k": v}
    return v


# (deeper ones are sent as raw text by the hand-written cases: json.dumps recurses)
deep_values = st.sampled_from([5, 40, 90, 99, 100, 101, 150, 400]).map(nested)

HOSTILE_PATHS = [
    "..", "../x.yaml", "../../etc/passwd", "/etc/passwd", "{outside}/x.yaml",
    "{outside}", "a\x00b.yaml", "x" * 300 + ".yaml", "é" * 200 + ".yaml",
    "a/" * 2000 + "x.yaml", "sub/" * 40 + "x.yaml", "door/secret.yaml", "door/new.yaml",
    "s.yaml", "sub/../../x.yaml", "..\\..\\x.yaml", "C:\\Windows\\x.yaml",
    "\\\\server\\share\\x.yaml", "~/x.yaml", "\ud800.yaml", "sub", ".", "", " ",
    "a.yaml/", "a.yaml/.", "CON.yaml", "nul", "x.yaml\n", "sub/.hidden.yaml",
    "avblocks-out/x.yaml", "%2e%2e/x.yaml",
]
components = st.one_of(st.sampled_from(["a", "sub", "..", ".", "", "door", "s.yaml",
                                        "x" * 256, "é" * 130, "a\x00b", "~", "\\"]),
                       st.text(min_size=1, max_size=10))
paths = st.one_of(
    st.sampled_from(HOSTILE_PATHS),
    st.tuples(st.lists(components, max_size=8).map("/".join),
              st.sampled_from(["", ".yaml", ".yml", ".toml", ".py"])).map("".join),
    st.text(max_size=40),
)


def _mutate(doc, data):
    """``doc`` with one section or value replaced by something hostile."""
    doc = json.loads(json.dumps(doc))
    where = data.draw(st.sampled_from(["name", "parameters", "blocks", "wires",
                                       "simulation", "editor", "block", "arg", "extra",
                                       "none"]), label="mutate")
    value = data.draw(st.one_of(json_values, deep_values), label="value")
    if where in ("block", "arg"):
        b = data.draw(st.sampled_from(sorted(doc["blocks"])), label="block")
        if where == "block":
            doc["blocks"][b] = value
        else:
            doc["blocks"][b][data.draw(st.sampled_from(["type", "pose0", "n", "gain",
                                                        "zz"]))] = value
    elif where == "extra":
        doc[data.draw(st.text(max_size=10), label="key")] = value
    elif where != "none":
        doc[where] = value
    return doc


def _args(op, data):
    out = {}
    for name in OPS[op]:
        how = data.draw(st.sampled_from(["good", "good", "hostile", "any", "leave"]),
                        label=f"{op}.{name}")
        if how == "leave":
            continue
        if how == "any":
            out[name] = data.draw(st.one_of(json_values, deep_values), label=name)
            continue
        if name == "document":
            out[name] = DOC if how == "good" else _mutate(DOC, data)
        elif name in ("path", "origin"):
            out[name] = (data.draw(st.sampled_from(["a.yaml", "sub/b.yaml", "new.yml"]))
                         if how == "good" else data.draw(paths, label=name))
        elif name == "builtin":
            out[name] = data.draw(st.sampled_from(["formation", "nest", "pursuit_py",
                                                   "nope", ""]))
        elif name in ("draft", "create"):
            out[name] = data.draw(st.booleans() if how == "good" else json_values)
        elif name in ("t_final", "dt"):
            out[name] = data.draw(st.sampled_from([0.5, 1, 0.05]) if how == "good" else
                                  st.one_of(st.floats(-1e300, 1e300), st.integers(),
                                            json_values))
        elif name == "backend":
            out[name] = data.draw(st.sampled_from(["numpy", "jax", "cuda", ""]))
        elif name == "format":
            out[name] = data.draw(st.sampled_from(["python", "svg", "png", "pdf", ""]))
        else:
            out[name] = data.draw(st.text(max_size=40))
    if data.draw(st.integers(0, 9), label="extra key") == 0:
        out[data.draw(st.text(max_size=10))] = data.draw(json_values)
    return out


# --------------------------------------------------------------- the server
def _memory(pid) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    return 0


class Fuzzed:
    """An ``avblocks edit`` process on a folder with links out of it, and
    the record of every answer."""

    def __init__(self, base):
        self.base = base
        self.root = base / "folder"
        self.outside = base / "outside"
        self.root.mkdir()
        self.outside.mkdir()
        (self.outside / "secret.yaml").write_text("name: secret\n")
        (self.root / "sub").mkdir()
        (self.root / "a.yaml").write_text(json.dumps(DOC))
        os.symlink(self.outside, self.root / "door")
        os.symlink(self.outside / "secret.yaml", self.root / "s.yaml")
        env = {**os.environ, "PYTHONPATH": str(SRC) + os.pathsep
               + os.environ.get("PYTHONPATH", ""), "BROWSER": "true",
               "TMPDIR": str(base / "tmp")}
        (base / "tmp").mkdir()
        self.before = self._outside_state()
        self.p = subprocess.Popen([sys.executable, "-m", "avblocks", "edit", "--no-browser"],
                                  cwd=self.root, stdout=subprocess.PIPE,
                                  stderr=subprocess.DEVNULL, text=True, env=env)
        m = re.match(r"avblocks editor: http://127\.0\.0\.1:(\d+)/([\w-]+)/",
                     self.p.stdout.readline())
        assert m, "the editor did not start"
        self.port, self.token = int(m.group(1)), m.group(2)
        self.tally = {"tried": 0, "ok": 0, "clean": 0, "500": 0, "other": 0}
        self.bad = []
        self.runs = []

    def _outside_state(self):
        return sorted(str(p.relative_to(self.base)) for p in self.base.rglob("*")
                      if self.root not in p.parents and p != self.root)

    def raw(self, method, path, body=None, ctype="application/json", timeout=120):
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=timeout)
        try:
            headers = {"content-type": ctype} if ctype else {}
            conn.request(method, path, body=body, headers=headers)
            r = conn.getresponse()
            return r.status, r.getheader("content-type") or "", r.read()
        except (ConnectionError, http.client.HTTPException, OSError) as e:
            return 0, "", repr(e).encode()
        finally:
            conn.close()

    def call(self, method, route, args=None, *, case=None, raw=None):
        """One request; its answer checked (or tallied) against API.md."""
        body = raw if raw is not None else (None if args is None else
                                            json.dumps(args).encode())
        status, ctype, data = self.raw(method, f"/{self.token}/api/{route}", body)
        self.check(status, ctype, data, case or (method, route, args))
        try:
            return status, json.loads(data)
        except ValueError:
            return status, None

    def check(self, status, ctype, data, case):
        self.tally["tried"] += 1
        why = None
        try:
            body = json.loads(data) if "json" in ctype else None
        except ValueError:
            body = None
        if status >= 500:
            self.tally["500"] += 1
            why = "5xx"
        elif status not in STATUSES:
            why = f"status {status}"
        elif status == 200:
            if body is None and not ctype.startswith("image/png"):
                why = "200 without JSON"
        elif not (isinstance(body, dict) and isinstance(body.get("error"), dict)
                  and isinstance(body["error"].get("message"), str)
                  and body["error"].get("kind") in KINDS):
            why = "error body not documented"
        if why is None:
            self.tally["ok" if status == 200 else "clean"] += 1
            return
        if why != "5xx":
            self.tally["other"] += 1
        self.bad.append((why, status, str(case)[:300],
                         bytes(data[:300]).decode("utf-8", "replace")))
        if not TALLY:
            raise AssertionError(f"{why}: {status} for {str(case)[:300]}: {data[:300]!r}")

    def settle(self):
        """Cancel the runs and stop the live views the fuzz started."""
        for rid in self.runs:
            self.raw("POST", f"/{self.token}/api/run/{rid}/cancel", b"{}")
        self.runs.clear()
        self.raw("POST", f"/{self.token}/api/live/stop", b"{}")

    def stop(self):
        self.settle()
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
        try:
            self.p.wait(60)
        except subprocess.TimeoutExpired:
            self.p.kill()


@pytest.fixture(scope="module")
def fuzzed(tmp_path_factory):
    pytest.importorskip("hypothesis")
    for m in ("starlette", "uvicorn"):
        try:
            __import__(m)
        except ImportError:
            if os.environ.get("CI"):
                pytest.fail(f"the editor fuzz needs {m} in CI")
            pytest.skip(f"needs {m}")
    if not Path("/proc/self/status").exists():
        if os.environ.get("CI"):
            pytest.fail("the editor fuzz reads /proc (Linux CI)")
        pytest.skip("reads the server's memory from /proc (Linux)")
    f = Fuzzed(tmp_path_factory.mktemp("fuzz"))
    # everything a call may import, imported first (the live view, JAX,
    # Matplotlib): what is measured after is what the calls keep
    f.call("GET", "palette")
    f.call("POST", "validate", {"document": DOC})
    f.call("POST", "export", {"document": DOC, "format": "png"})
    for backend in ("numpy", "jax"):
        status, body = f.call("POST", "run", {"document": DOC, "backend": backend})
        if status == 200:
            while f.call("GET", f"run/{body['run']}")[1]["status"] == "running":
                time.sleep(0.1)
    f.call("POST", "live", {"document": DOC})
    f.settle()
    f.memory0 = _memory(f.p.pid)
    try:
        yield f
    finally:
        f.stop()
        if TALLY:
            Path(TALLY).write_text(json.dumps({**f.tally, "bad": f.bad[:5000]}, indent=1))


def _one(fuzzed, data):
    kind = data.draw(st.sampled_from(["op"] * 6 + ["get", "run-route", "live-stop"]),
                     label="kind")
    if kind == "get":
        fuzzed.call("GET", data.draw(st.sampled_from(GETS)))
        return
    if kind == "live-stop":
        fuzzed.call("POST", "live/stop", data.draw(st.one_of(
            st.just({}), st.fixed_dictionaries({"url": st.one_of(st.text(max_size=30),
                                                                 json_values)}))))
        return
    if kind == "run-route":
        rid = data.draw(st.one_of(st.sampled_from(fuzzed.runs or ["abc"]),
                                  st.text(alphabet="abcdef0123456789", max_size=12),
                                  st.sampled_from(["..", "%00", "x" * 300])), label="run")
        what = data.draw(st.sampled_from(["", "/cancel", "/signal?name=fleet.pose",
                                          "/signal?name=", "/signal?name=%00",
                                          "/file/x.png", "/file/..%2f..%2fa.yaml"]))
        rid = rid.replace("/", "%2F").replace("?", "%3F").replace("#", "%23")
        rid = "".join(c if 32 < ord(c) < 127 else f"%{ord(c) & 0xff:02X}" for c in rid)
        if what == "/cancel":
            fuzzed.call("POST", f"run/{rid}{what}", {})
        else:
            fuzzed.call("GET", f"run/{rid}{what}")
        return
    op = data.draw(st.sampled_from(sorted(OPS)), label="op")
    args = _args(op, data)
    for k, v in list(args.items()):
        if isinstance(v, str) and "{outside}" in v:
            args[k] = v.replace("{outside}", str(fuzzed.outside))
    if data.draw(st.integers(0, 19), label="not an object") == 0:
        args = data.draw(json_values)
    status, body = fuzzed.call("POST", op, args)
    if op == "run" and status == 200:
        fuzzed.runs.append(body["run"])
        fuzzed.settle()
    if op == "live" and status == 200:
        fuzzed.settle()


@FAST
@given(data=st.data())
def test_fuzz_the_api(fuzzed, data):
    _one(fuzzed, data)


@pytest.mark.slow
@LONG
@given(data=st.data())
def test_fuzz_the_api_long(fuzzed, data):
    _one(fuzzed, data)


def _chunked(fuzzed, total):
    """A chunked body of ``total`` bytes; the raw answer (status line first)."""
    s = socket.create_connection(("127.0.0.1", fuzzed.port), timeout=60)
    got = bytearray()

    def read():
        try:
            while b := s.recv(65536):
                got.extend(b)
        except OSError:
            pass

    t = threading.Thread(target=read, daemon=True)
    s.sendall((f"POST /{fuzzed.token}/api/save HTTP/1.1\r\nHost: 127.0.0.1:{fuzzed.port}"
               "\r\nContent-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n"
               ).encode())
    t.start()
    block = b"[" * (1 << 20)
    try:
        for _ in range(total >> 20):
            s.sendall(b"100000\r\n" + block + b"\r\n")
        s.sendall(b"0\r\n\r\n")
    except OSError:
        pass
    t.join(60)
    s.close()
    return bytes(got)


def test_hand_written_hostile_requests(fuzzed):
    """What hypothesis rarely reaches: nesting past the limit, huge and
    chunked bodies, NUL and long names, bodies that are not JSON."""
    f = fuzzed
    for depth in (100, 101, 500, 990, 1000, 5000, 100_000):
        for op in ("validate", "save", "run", "export", "live", "load"):
            f.call("POST", op, raw=(b'{"path": "x.yaml", "document": '
                                    + b"[" * depth + b"]" * depth + b"}"),
                   case=(op, "depth", depth))
    for raw in (b"", b"{", b"[]", b"null", b"\xff\xfe", b'{"a": NaN}', b"1" * 5000,
                b'{"document": ' + b"1" * 5000 + b"}", b'{"document": {"x": "\\ud800"}}',
                b'{"path": "\\u0000.yaml", "document": {}}', b"{}" * 1000,
                b'{"document": [' + b"0," * 1_200_000 + b"0]}"):
        for op in ("validate", "save", "load"):
            f.call("POST", op, raw=raw, case=(op, raw[:30]))
    for path in ("a\x00b.yaml", "x" * 300 + ".yaml", "a/" * 2000 + "x.yaml",
                 "door/secret.yaml", "s.yaml", str(f.outside / "x.yaml")):
        for op, args in (("save", {"path": path, "document": DOC, "draft": True}),
                         ("load", {"path": path}),
                         ("save", {"path": "ok.yaml", "document": DOC, "origin": path})):
            f.call("POST", op, args)
    f.call("POST", "load", {"builtin": {"x": 1}})
    # a body announced too large, and one too large in fact: 413, nothing read on
    status, ctype, data = f.raw("POST", f"/{f.token}/api/validate",
                                b"[" * (9 * 1024 * 1024))
    if status:                          # (the server may hang up first)
        f.check(status, ctype, data, "9 MB body")
    answer = _chunked(f, 64 * 1024 * 1024)
    head, _, rest = answer.partition(b"\r\n\r\n")
    m = re.match(rb"HTTP/1\.1 (\d+)", head)
    f.check(int(m.group(1)) if m else 0, "application/json", rest[:rest.find(b"}}") + 2],
            "64 MB chunked body")
    # a POST that is not JSON (a form, text/plain): refused unread
    status, ctype, data = f.raw("POST", f"/{f.token}/api/save",
                                json.dumps({"path": "t.yaml", "document": DOC,
                                            "draft": True}).encode(), ctype="text/plain")
    f.check(status, ctype, data, "text/plain")
    assert status == 415 or TALLY


def test_concurrent_saves_validations_and_runs(fuzzed):
    """Eight clients at once: saves of one file, validations, runs started
    and cancelled, files listed; every answer documented, the file whole."""
    f = fuzzed
    answers = []

    def client(i):
        for j in range(6):
            which = (i + j) % 4
            if which == 0:
                answers.append(f.call("POST", "save", {"path": "sub/same.yaml",
                                                       "document": DOC, "draft": True}))
            elif which == 1:
                answers.append(f.call("POST", "validate", {"document": DOC}))
            elif which == 2:
                status, body = f.call("POST", "run", {"document": DOC, "t_final": 0.5})
                if status == 200:
                    f.call("POST", f"run/{body['run']}/cancel", {})
                answers.append((status, body))
            else:
                answers.append(f.call("GET", "files"))

    threads = [threading.Thread(target=client, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(300)
    assert len(answers) == 48
    assert {s for s, _b in answers} <= {200, 409}        # 409: two runs going already
    text = (f.root / "sub" / "same.yaml").read_text()
    assert text.startswith("name: tiny") and text.rstrip().endswith("drive: [200, 0]")


def test_after_the_fuzz_nothing_outside_and_memory_bounded(fuzzed):
    """Runs last (the file's order): the state the fuzz above left."""
    f = fuzzed
    f.settle()
    time.sleep(1.0)
    grown = _memory(f.p.pid) - f.memory0
    print(f"\neditor fuzz: {f.tally}; server RSS {f.memory0 / 2**20:.0f} MB -> "
          f"+{grown / 2**20:.0f} MB")
    if TALLY:
        return
    now = f._outside_state()
    assert now == f.before, set(now) ^ set(f.before)          # nothing new outside
    assert (f.outside / "secret.yaml").read_text() == "name: secret\n"
    assert not [p for p in f.root.rglob("*") if ".part" in p.name]
    assert grown < 300 * 2**20, f"the server grew by {grown / 2**20:.0f} MB"
    assert f.tally["500"] == 0 and f.tally["other"] == 0 and not f.bad
