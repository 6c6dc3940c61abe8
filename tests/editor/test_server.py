"""The editor's HTTP API on a real uvicorn server on loopback (real requests)."""

from __future__ import annotations

import copy
import json
import time
from pathlib import Path

import numpy as np
import pytest

from avblocks.core.errors import AlgebraicLoopError, ParameterError, ShapeError
from avblocks.scenarios.loader import builtin_scenarios

P2P = {"type": "controllers.PointToPoint",
       "waypoints": {"random_waypoints": {"n": "$agents", "count": 2, "area": [20, 20],
                                          "seed": "$seed"}},
       "n": "$agents"}
FLEET = {"type": "vehicles.Unicycle",
         "pose0": {"random_poses": {"n": "$agents", "area": [20, 20], "seed": "$seed"}}}


def _doc(blocks, wires, **extra):
    return {"name": "drawn", "parameters": {"agents": 4, "seed": 1},
            "blocks": copy.deepcopy(blocks), "wires": [list(w) for w in wires],
            "simulation": {"t_final": 2.0, "dt": 0.05}, **extra}


def _errors(srv, doc):
    status, body = srv.post("validate", {"document": doc})
    assert status == 200, body
    return body


# ------------------------------------------------------------------ the token
def test_403_without_or_with_a_wrong_token(editor_server):
    srv = editor_server
    for url in (srv.base, srv.base + "api/palette", srv.base + "assets/x.js",
                srv.base + "x" + srv.token + "/api/palette",
                srv.base + srv.token[:-1] + "/api/palette",
                srv.base + srv.token + "x/api/palette"):
        status, _ = srv.request("GET", None, url=url)
        assert status == 403, url
    status, _ = srv.request("POST", None, url=srv.base + "nope/api/save",
                            body={"path": "x.yaml", "document": {}})
    assert status == 403
    assert not list(srv.root.iterdir())          # nothing was written
    status, body = srv.get("palette")
    assert status == 200 and body["families"]


def test_palette_lists_every_registry_block(editor_server):
    from avblocks.scenarios.loader import block_registry
    status, body = editor_server.get("palette")
    assert status == 200
    types = [b["type"] for f in body["families"] for b in f["blocks"]]
    assert set(types) == set(block_registry(interfaces=True))   # the loader's registry, no more
    names = [f["name"] for f in body["families"]]
    order = ["vehicles", "controllers", "environment", "tasks", "blocks", "viz", "interfaces"]
    assert names == [n for n in order if n in names]
    assert "vehicles.Unicycle" in types and "blocks.Function" not in types


# --------------------------------------------------------------- validation
def test_load_formation_validates_with_its_signal_shapes(editor_server):
    status, loaded = editor_server.post("load", {"builtin": "formation"})
    assert status == 200 and loaded["path"] is None and len(loaded["revision"]) == 32
    doc = loaded["document"]
    body = _errors(editor_server, doc)
    assert body["ok"] and body["errors"] == []
    n = doc["parameters"]["followers"] + 1            # leader + followers
    assert body["signals"]["fleet.pose"] == {"shape": f"({n}, 3)", "dtype": "float64"}
    assert body["signals"]["drive.cmd"]["shape"] == f"({n}, 2)"


def test_a_wrong_wire_names_block_port_wire_with_the_librarys_message(editor_server):
    import avblocks as av
    from avblocks.controllers import PointToPoint
    from avblocks.vehicles import Unicycle
    doc = _doc({"fleet": FLEET, "drive": P2P},
               [["fleet.pose", "drive.pose"], ["drive.cmd", "fleet.cmd"],
                ["fleet.pose", "drive.pose"]])
    doc["wires"][0] = ["drive.cmd", "drive.pose"]      # (4, 2) into (4, 3)
    doc["wires"].pop()
    body = _errors(editor_server, doc)
    assert not body["ok"]
    # the same wire made with the Python API: the library's own message
    d = av.Diagram("drawn")
    d.add(Unicycle(pose0=np.zeros((4, 3))), name="fleet")
    drive = d.add(PointToPoint(np.zeros((4, 2, 2)), n=4), name="drive")
    with pytest.raises(ShapeError) as truth:
        d.connect(drive.cmd, drive.pose)
    err, = body["errors"]
    assert err["message"] == str(truth.value)
    assert (err["kind"], err["block"], err["port"]) == ("ShapeError", "drive", "pose")
    assert err["wire"] == ["drive.cmd", "drive.pose"]
    assert body["signals"]["fleet.pose"]["shape"] == "(4, 3)"   # shapes still shown


def test_an_agent_count_mismatch_names_the_wire(editor_server):
    import avblocks as av
    from avblocks.controllers import PointToPoint
    from avblocks.vehicles import Unicycle
    six = copy.deepcopy(P2P)
    six["n"] = 6
    six["waypoints"]["random_waypoints"]["n"] = 6
    doc = _doc({"fleet": FLEET, "drive": six},
               [["fleet.pose", "drive.pose"], ["drive.cmd", "fleet.cmd"]])
    body = _errors(editor_server, doc)
    d = av.Diagram("drawn")
    fleet = d.add(Unicycle(pose0=np.zeros((4, 3))), name="fleet")
    drive = d.add(PointToPoint(np.zeros((6, 2, 2)), n=6), name="drive")
    truths = []
    for a, b in ((fleet.pose, drive.pose), (drive.cmd, fleet.cmd)):
        with pytest.raises(ShapeError) as t:
            d.connect(a, b)
        truths.append(str(t.value))
    assert [e["message"] for e in body["errors"]] == truths
    assert "agent count mismatch" in truths[0]
    assert [e["wire"] for e in body["errors"]] == doc["wires"]      # both wires marked
    assert [(e["block"], e["port"]) for e in body["errors"]] == [("drive", "pose"),
                                                                 ("fleet", "cmd")]


def test_every_unconnected_input_is_reported(editor_server):
    doc = _doc({"fleet": FLEET, "drive": P2P}, [])
    body = _errors(editor_server, doc)
    got = {(e["block"], e["port"]) for e in body["errors"]}
    assert got == {("fleet", "cmd"), ("drive", "pose")}        # both, not the first
    assert all(e["kind"] == "WiringError" and "not connected" in e["message"]
               for e in body["errors"])


def test_an_algebraic_loop_comes_with_its_cycle(editor_server):
    import avblocks as av
    from avblocks.blocks import Gain
    doc = _doc({"a": {"type": "blocks.Gain", "k": 2.0}, "b": {"type": "blocks.Gain"}},
               [["a.y", "b.u"], ["b.y", "a.u"]])
    body = _errors(editor_server, doc)
    err, = body["errors"]
    d = av.Diagram()
    a, b = d.add(Gain(2.0), name="a"), d.add(Gain(), name="b")
    d.connect(a.y, b.u)
    d.connect(b.y, a.u)
    with pytest.raises(AlgebraicLoopError) as truth:
        d.build()
    assert err["kind"] == "AlgebraicLoopError"
    assert err["message"] == str(truth.value)
    pairs = list(zip(err["cycle"][::2], err["cycle"][1::2]))
    assert sorted(pairs) == [("a.y", "b.u"), ("b.y", "a.u")]


def test_unknown_out_of_range_parameters_and_types(editor_server):
    from avblocks.vehicles import Unicycle
    bad_speed = dict(FLEET, v_max=-1.0)
    doc = _doc({"fleet": bad_speed, "drive": dict(P2P, gian=2.0),
                "ghost": {"type": "vehicles.Unicylce"}},
               [["fleet.pose", "drive.pose"], ["drive.cmd", "fleet.cmd"]])
    body = _errors(editor_server, doc)
    by_block = {e["block"]: e for e in body["errors"]}
    assert set(by_block) == {"fleet", "drive", "ghost"}
    assert by_block["drive"]["param"] == "gian"
    assert "did you mean 'gain'" in by_block["drive"]["message"]
    with pytest.raises(ParameterError) as truth:
        Unicycle(pose0=np.zeros((4, 3)), v_max=-1.0)
    assert by_block["fleet"]["param"] == truth.value.param == "v_max"
    assert by_block["fleet"]["message"] == str(truth.value)
    assert "vehicles.Unicycle" in by_block["ghost"]["message"]     # did you mean
    # a generator's failure names the block and argument, with the loader's words
    doc["blocks"]["more"] = {"type": "blocks.Gain",
                             "k": {"random_poses": {"n": -1, "area": [1, 1]}}}
    doc["wires"].append(["fleet.pose", "nowhere.u"])
    body = _errors(editor_server, doc)
    gen, = [e for e in body["errors"] if e["block"] == "more"]
    assert (gen["param"], gen["kind"]) == ("k", "ParameterError")
    assert gen["message"].startswith("blocks.more.k: 'random_poses' failed: in parameter "
                                     "'n': out of range")
    wire, = [e for e in body["errors"] if e["wire"] == ["fleet.pose", "nowhere.u"]]
    assert "unknown block 'nowhere'" in wire["message"]
    # the document came back unaltered: validation never edits it
    assert doc["blocks"]["drive"]["gian"] == 2.0


# ---------------------------------------------------------------- files
def test_save_outside_the_folder_or_not_yaml_is_refused(editor_server, tmp_path_factory):
    doc = _doc({"fleet": FLEET}, [])
    outside = tmp_path_factory.mktemp("elsewhere") / "x.yaml"
    for path in ("../x.yaml", str(outside), "sub/../../x.yaml", "x.py", "x.yaml.txt"):
        status, body = editor_server.post("save", {"path": path, "document": doc,
                                                   "draft": True})
        assert status == 400, path
        assert body["error"]["kind"] in ("OutsideFolder", "BadPath")
    assert not outside.exists()
    assert not (editor_server.root.parent / "x.yaml").exists()
    status, body = editor_server.post("load", {"path": "../../etc/passwd"})
    assert status == 400


def test_invalid_document_saved_only_as_a_draft_and_409_on_change(editor_server):
    doc = _doc({"fleet": FLEET}, [])          # fleet.cmd unconnected
    status, body = editor_server.post("save", {"path": "d.yaml", "document": doc})
    assert status == 400 and body["error"]["kind"] == "InvalidDiagram"
    assert body["error"]["errors"][0]["port"] == "cmd"
    status, saved = editor_server.post("save", {"path": "d.yaml", "document": doc,
                                                "draft": True})
    assert status == 200 and saved["draft"] is True
    status, loaded = editor_server.post("load", {"path": "d.yaml"})
    assert loaded["document"]["blocks"] == doc["blocks"]
    assert loaded["revision"] == saved["revision"]
    (editor_server.root / "d.yaml").write_text("name: changed\n")
    status, body = editor_server.post("save", {"path": "d.yaml", "document": doc,
                                               "draft": True,
                                               "revision": saved["revision"]})
    assert status == 409
    status, files = editor_server.get("files")
    assert {"path": "d.yaml", "name": "d"} in files["files"]



TEAM_FILE = """\
# a team: one fleet, one law
name: team
parameters:
  agents: 5   # how many
  seed: 1
blocks:
  fleet:
    type: vehicles.Unicycle
    pose0: {random_poses: {n: $agents, area: [20, 20], seed: 3}}
  drive:
    type: controllers.PointToPoint
    n: $agents
    waypoints: {random_waypoints: {n: $agents, count: 2, area: [20, 20], seed: 4}}
wires:
  - [fleet.pose, drive.pose]   # the law sees the pose
  - [drive.cmd, fleet.cmd]
simulation: {t_final: 5, dt: 0.05}
"""


def test_save_as_from_a_file_keeps_its_text_and_a_stale_revision_is_409(editor_server):
    """What the page's Save as sends (``origin``: the file it was loaded from)
    and what its Save sends (that file's revision): the new file is the old
    one's text with only the edit changed; saving over a file changed on
    disk since it was loaded is refused, origin or not, and writes nothing."""
    a = editor_server.root / "a.yaml"
    a.write_text(TEAM_FILE)
    status, loaded = editor_server.post("load", {"path": "a.yaml"})
    assert status == 200, loaded
    doc = copy.deepcopy(loaded["document"])
    doc["parameters"]["agents"] = 9
    status, saved = editor_server.post("save", {"path": "sub/b.yaml", "document": doc,
                                                "revision": None, "draft": False,
                                                "origin": "a.yaml"})
    assert status == 200, saved
    b = (editor_server.root / "sub" / "b.yaml").read_text()
    lines = TEAM_FILE.splitlines()
    assert b.splitlines()[:len(lines)] != lines
    changed = [(x, y) for x, y in zip(lines, b.splitlines()) if x != y]
    assert len(changed) == 1, changed                    # comments, forms kept
    assert changed[0][1].split() == ["agents:", "9", "#", "how", "many"]
    assert a.read_text() == TEAM_FILE                     # the origin is only read
    # Save over a.yaml with the revision it was loaded with, after a change on disk: 409
    a.write_text(TEAM_FILE.replace("seed: 1", "seed: 2"))
    for extra in ({}, {"origin": "a.yaml"}):
        status, body = editor_server.post("save", {"path": "a.yaml", "document": doc,
                                                   "revision": loaded["revision"],
                                                   "draft": False, **extra})
        assert status == 409 and body["error"]["kind"] == "Conflict", body
        assert a.read_text() == TEAM_FILE.replace("seed: 1", "seed: 2")
    # with the revision on disk now, the save goes through and keeps that file's change
    status, now = editor_server.post("load", {"path": "a.yaml"})
    status, body = editor_server.post("save", {"path": "a.yaml", "document": now["document"],
                                               "revision": now["revision"], "draft": False})
    assert status == 200 and a.read_text() == TEAM_FILE.replace("seed: 1", "seed: 2")


def test_save_as_onto_another_existing_file_asks_first(editor_server):
    """Save as sends ``create``: an existing file at that path is a 409
    ``Exists`` and stays as it was; without ``create`` (the page's
    "Overwrite") it is replaced; a new path is written."""
    (editor_server.root / "keep.yaml").write_text(TEAM_FILE)
    status, loaded = editor_server.post("load", {"builtin": "waypoints"})
    doc = loaded["document"]
    status, body = editor_server.post("save", {"path": "keep.yaml", "document": doc,
                                               "origin": "waypoints", "create": True})
    assert status == 409 and body["error"]["kind"] == "Exists", body
    assert (editor_server.root / "keep.yaml").read_text() == TEAM_FILE
    status, body = editor_server.post("save", {"path": "fresh.yaml", "document": doc,
                                               "origin": "waypoints", "create": True})
    assert status == 200, body
    shipped = builtin_scenarios()["waypoints"].read_text()
    assert (editor_server.root / "fresh.yaml").read_text() == shipped
    status, body = editor_server.post("save", {"path": "keep.yaml", "document": doc,
                                               "origin": "waypoints"})
    assert status == 200, body
    status, again = editor_server.post("load", {"path": "keep.yaml"})
    assert again["document"]["blocks"] == doc["blocks"]
    assert again["document"]["parameters"] == doc["parameters"]


def _summary(tmp, target, sets=()):
    from avblocks.cli import main
    out = tmp / f"out-{Path(str(target)).stem}-{len(list(tmp.iterdir()))}"
    argv = ["run", str(target), "--out", str(out), "--quiet"]
    for s in sets:
        argv += ["--set", s]
    assert main(argv) == 0
    return json.loads((out / "summary.json").read_text())


@pytest.mark.parametrize("name", sorted(builtin_scenarios()))
def test_saved_case_study_runs_to_the_same_summary(editor_server, name, tmp_path_factory,
                                                    request):
    if name == "uav_tracking":
        request.getfixturevalue("mujoco_extra")
    status, loaded = editor_server.post("load", {"builtin": name})
    doc = loaded["document"]
    status, saved = editor_server.post("save", {"path": f"mine/{name}.yaml",
                                                "document": doc})
    assert status == 200, saved
    tmp = tmp_path_factory.mktemp("runs")
    a = _summary(tmp, name, ["t_final=6"])
    b = _summary(tmp, editor_server.root / "mine" / f"{name}.yaml", ["t_final=6"])
    for k in ("status", "agents", "simulated_s", "outcome", "numbers"):
        assert a[k] == b[k], k


@pytest.mark.parametrize("name", ["formation", "flocking", "pursuit", "spread", "navigation"])
def test_save_as_keeps_the_files_comments_and_changes_only_the_edit(editor_server, name):
    status, loaded = editor_server.post("load", {"builtin": name})
    doc = loaded["document"]
    status, saved = editor_server.post("save", {"path": f"mine/{name}.yaml",
                                                "document": doc, "origin": name})
    assert status == 200, saved
    # unchanged, "save as" from the built-in keeps its file as it is (comments,
    # anchors, references): the bytes of the shipped file
    from avblocks.scenarios.loader import builtin_scenarios
    shipped = builtin_scenarios()[name].read_text()
    assert (editor_server.root / "mine" / f"{name}.yaml").read_text() == shipped
    # an edit changes only what was edited
    doc2 = copy.deepcopy(doc)
    first = next(iter(doc2["parameters"]))
    doc2["parameters"]["seed"] = 7
    status, saved2 = editor_server.post("save", {"path": f"mine/{name}.yaml",
                                                 "document": doc2,
                                                 "revision": saved["revision"]})
    assert status == 200, saved2
    text = (editor_server.root / "mine" / f"{name}.yaml").read_text()
    changed = [(a, b) for a, b in zip(shipped.splitlines(), text.splitlines()) if a != b]
    assert len(changed) == 1 and "seed" in changed[0][1] and "7" in changed[0][1], changed
    assert first in text
    status, saved = editor_server.post("save", {"path": f"mine/{name}.yaml",
                                                "document": doc,
                                                "revision": saved2["revision"]})
    assert status == 200                       # and back: the shipped file again
    assert (editor_server.root / "mine" / f"{name}.yaml").read_text() == shipped


# ------------------------------------------------------------------ runs
def _wait(srv, rid, timeout=120):
    seen = []
    t_end = time.monotonic() + timeout
    while True:
        status, st = srv.get(f"run/{rid}")
        assert status == 200
        seen.append(st["progress"])
        if st["status"] != "running" or time.monotonic() > t_end:
            return st, seen
        time.sleep(0.05)


def test_run_reports_progress_outcome_figures_and_signals(editor_server):
    from avblocks.core.frontend import simulate
    from avblocks.scenarios.targets import load_any
    status, loaded = editor_server.post("load", {"builtin": "formation"})
    status, body = editor_server.post("run", {"document": loaded["document"],
                                              "backend": "numpy", "t_final": 8})
    assert status == 200
    st, seen = _wait(editor_server, body["run"])
    assert st["status"] == "done", st
    assert st["progress"] == 1.0 and st["t"] == pytest.approx(8.0)
    assert seen == sorted(seen)                            # progress never goes back
    # the outcome line of the same scenario run through the CLI's path
    loaded2 = load_any("formation", {"t_final": 8})
    d, sim = loaded2[0], loaded2[1]
    res = simulate(d, progress=False, **sim)
    line, numbers = loaded2.hooks.outcome(res)
    assert st["outcome"] == line
    assert st["numbers"]["formation_error_end_m"] == pytest.approx(
        numbers["formation_error_end_m"], rel=1e-12)
    fig = st["figures"][0]
    status, png = editor_server.request("GET", None, url=editor_server.url + fig["url"])
    assert status == 200 and png[:8] == b"\x89PNG\r\n\x1a\n"
    status, sig = editor_server.get(f"run/{body['run']}/signal?name=fleet.pose")
    assert status == 200
    t = np.asarray(sig["t"])
    idx = np.searchsorted(res.t, t)
    np.testing.assert_array_equal(res.t[idx], t)
    np.testing.assert_array_equal(np.asarray(sig["values"]), res["fleet.pose"][idx])
    assert t[0] == res.t[0] and t[-1] == res.t[-1] and len(t) <= 2001
    status, body2 = editor_server.get(f"run/{body['run']}/signal?name=nope.x")
    assert status == 404


def test_a_run_can_be_cancelled(editor_server):
    status, loaded = editor_server.post("load", {"builtin": "nest"})
    status, body = editor_server.post("run", {"document": loaded["document"],
                                              "t_final": 600})
    rid = body["run"]
    time.sleep(0.3)
    status, _ = editor_server.post(f"run/{rid}/cancel")
    assert status == 200
    st, _ = _wait(editor_server, rid, timeout=60)
    assert st["status"] == "cancelled"
    assert st["t"] < 600


def test_progress_callback_counts_every_step():
    import avblocks as av
    from avblocks.blocks import Constant, Integrator
    d = av.Diagram()
    c, i = d.add(Constant(np.ones((2, 1))), name="c"), d.add(
        Integrator(np.zeros((2, 1))), name="i")
    d.connect(c.y, i.u)
    calls = []
    res = av.simulate(d, t_final=1.0, dt=0.01, progress=lambda k, n: calls.append((k, n)))
    assert calls[-1] == (100, 100) and len(calls) == 100
    assert [k for k, _ in calls] == list(range(1, 101))
    np.testing.assert_allclose(res["i.y"][-1], 1.0)     # integral of 1 over 1 s


def test_invalid_diagram_does_not_run(editor_server):
    status, body = editor_server.post("run", {"document": _doc({"fleet": FLEET}, [])})
    assert status == 400 and body["error"]["kind"] == "InvalidDiagram"
    status, body = editor_server.post("run", {"document": _doc({"fleet": FLEET}, []),
                                              "backend": "cuda"})
    assert status == 400


def test_export_picture(editor_server):
    import base64
    status, loaded = editor_server.post("load", {"builtin": "nest"})
    status, body = editor_server.post("export", {"document": loaded["document"],
                                                 "format": "svg"})
    assert status == 200
    svg = base64.b64decode(body["data_url"].split(",", 1)[1]).decode()
    assert svg.lstrip().startswith("<?xml") and "bees" in svg and "gossip" in svg
    assert "wire bees.pose -&gt; walk.pose" in svg or "wire bees.pose -> walk.pose" in svg
    status, body = editor_server.post("export", {"document": loaded["document"],
                                                 "format": "png"})
    assert status == 200 and body["data_url"].startswith("data:image/png;base64,")
    png = base64.b64decode(body["data_url"].split(",", 1)[1])
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    import io

    import matplotlib.image as mpimg
    img = mpimg.imread(io.BytesIO(png))
    assert img.shape[0] > 100 and img.shape[1] > 100 and img[..., :3].std() > 0.01


def test_bad_requests_get_4xx_with_a_reason(editor_server):
    import urllib.error
    import urllib.request
    srv = editor_server
    status, body = srv.post("validate", {})
    assert status == 400 and body["error"]["kind"] == "BadRequest"
    status, body = srv.post("validate", {"document": [1, 2]})
    assert status == 400 and body["error"]["kind"] == "BadDocument"
    status, body = srv.post("validate", {"document": {}, "evil": "__import__('os')"})
    assert status == 400 and "evil" in body["error"]["message"]
    status, body = srv.post("frobnicate", {})
    assert status == 404
    status, body = srv.get("run/nope")
    assert status == 404 and body["error"]["kind"] == "NotFound"
    req = urllib.request.Request(srv.url + "api/validate", data=b"{not json",
                                 method="POST", headers={"content-type": "application/json"})
    try:
        urllib.request.urlopen(req, timeout=30)
    except urllib.error.HTTPError as e:
        assert e.code == 400 and b"not JSON" in e.read()
    else:
        raise AssertionError("accepted a body that is not JSON")
    # a POST that is not declared JSON (a form, text/plain) is refused unread
    req = urllib.request.Request(srv.url + "api/validate", data=b'{"document": {}}',
                                 method="POST")
    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.urlopen(req, timeout=30)
    assert e.value.code == 415
    assert json.loads(e.value.read())["error"]["kind"] == "UnsupportedMediaType"
    # a body announced over 8 MB is refused before it is read
    import http.client
    port = int(srv.base.rsplit(":", 1)[1].strip("/"))
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    conn.putrequest("POST", f"/{srv.token}/api/validate")
    conn.putheader("content-type", "application/json")
    conn.putheader("content-length", str(9 * 1024 * 1024))
    conn.endheaders()
    r = conn.getresponse()
    assert r.status == 413 and b"too large" in r.read()
    conn.close()


def test_a_bad_numeric_parameter_names_block_and_parameter(editor_server):
    from avblocks.core.errors import ScenarioError
    from avblocks.scenarios.loader import Scenario, builtin_scenarios
    status, loaded = editor_server.post("load", {"builtin": "nest"})
    doc = loaded["document"]
    doc["params"] = {"walk.gain": -5}
    body = _errors(editor_server, doc)
    err, = body["errors"]
    assert (err["block"], err["param"], err["kind"]) == ("walk", "gain", "ParameterError")
    with pytest.raises(ScenarioError) as truth:            # what `avblocks run` says
        Scenario(dict(doc), str(builtin_scenarios()["nest"])).build(
            output_dir=editor_server.root / "o")
    assert err["message"] in str(truth.value)
    assert "below its lower bound" in err["message"]
