"""``av.edit()`` in a kernel, without a browser: custom messages go in and out
through ipywidgets' comm layer (a recording ``comm`` such as a kernel installs)."""

from __future__ import annotations

import copy
import itertools

import numpy as np
import pytest


@pytest.fixture(autouse=True)
def _needs_anywidget(need_editor_extra):
    need_editor_extra("anywidget", "ipywidgets", "comm")


@pytest.fixture
def sent(monkeypatch):
    """Every message the widgets send, as a kernel's comm would publish them."""
    import comm
    from comm.base_comm import BaseComm
    out = []

    class RecordingComm(BaseComm):
        def publish_msg(self, msg_type, data=None, metadata=None, buffers=None, **keys):
            out.append((msg_type, data))

    monkeypatch.setattr(comm, "create_comm", lambda *a, **k: RecordingComm(*a, **k))
    return out


_ids = itertools.count(1)


def _ask(w, sent, op, **args):
    """Send ``{id, op, args}`` from the 'front end' through the widget's comm;
    return the widget's reply."""
    rid = next(_ids)
    msg = {"content": {"comm_id": w.comm.comm_id,
                       "data": {"method": "custom",
                                "content": {"id": rid, "op": op, "args": args}}},
           "buffers": []}
    w.comm.handle_msg(msg)
    replies = [d["content"] for t, d in sent if t == "comm_msg" and d.get("method") ==
               "custom" and d["content"].get("id") == rid]
    assert len(replies) == 1
    return replies[0]


def test_edits_through_messages_update_the_kernels_diagram(sent, tmp_path):
    import avblocks as av
    w = av.edit("formation", root=tmp_path)
    assert w.diagram is not None
    assert w.diagram["fleet"].block.output_ports["pose"].shape == (5, 3)
    doc = copy.deepcopy(w.document)
    doc["parameters"]["followers"] = 7                   # a team of 8
    reply = _ask(w, sent, "validate", document=doc)
    assert reply["ok"] and reply["result"]["ok"]
    assert reply["result"]["signals"]["fleet.pose"]["shape"] == "(8, 3)"
    assert w.document["parameters"]["followers"] == 7
    assert w.diagram["fleet"].block.output_ports["pose"].shape == (8, 3)
    res = av.simulate(w.diagram, **{**w.simulation, "t_final": 0.2})
    assert res["fleet.pose"].shape[1:] == (8, 3)
    # an invalid edit: errors come back, the diagram and document stay the last valid
    bad = copy.deepcopy(doc)
    bad["wires"] = [x for x in bad["wires"] if x[1] != "fleet.cmd"]
    reply = _ask(w, sent, "validate", document=bad)
    assert reply["ok"] and not reply["result"]["ok"]
    assert {(e["block"], e["port"]) for e in reply["result"]["errors"]} == {("fleet", "cmd")}
    assert w.errors == reply["result"]["errors"]
    assert ["lf.cmd", "fleet.cmd"] in w.document["wires"]
    # a failing operation answers {ok: false, error}
    reply = _ask(w, sent, "save", path="../out.yaml", document=doc)
    assert reply["ok"] is False and reply["error"]["kind"] == "OutsideFolder"
    reply = _ask(w, sent, "nope")
    assert reply["ok"] is False and reply["error"]["kind"] == "NotFound"


def test_widget_runs_with_figures_as_data_urls(sent, tmp_path):
    import avblocks as av
    w = av.edit("nest", root=tmp_path)
    reply = _ask(w, sent, "run", document=w.document, t_final=3)
    rid = reply["result"]["run"]
    w.service.wait(rid, 120)
    st = _ask(w, sent, "status", run=rid)["result"]
    assert st["status"] == "done"
    url = st["figures"][0]["url"]
    assert url.startswith("data:image/png;base64,")
    import base64
    assert base64.b64decode(url.split(",", 1)[1])[:4] == b"\x89PNG"
    sig = _ask(w, sent, "signal", run=rid, name="gossip.informed")["result"]
    assert np.asarray(sig["values"]).shape[0] == len(sig["t"])


def test_widget_front_end_is_the_bundle(tmp_path):
    import avblocks as av
    from avblocks.editor.widget import WIDGET_JS
    w = av.edit(None, root=tmp_path)
    assert w.document["parameters"] == {"agents": 15, "seed": 1}
    assert w.document["simulation"] == {"t_final": 30, "dt": 0.02}
    if WIDGET_JS.is_file():
        assert "render" in WIDGET_JS.read_text()


def test_a_diagram_built_in_python_opens_and_runs_the_same(sent, tmp_path):
    import avblocks as av
    from avblocks.controllers import PointToPoint
    from avblocks.utility import random_poses
    from avblocks.vehicles import Unicycle
    d = av.Diagram("mine")
    fleet = d.add(Unicycle(random_poses(5, area=(20, 20), seed=3), v_max=2.0), name="fleet")
    rng = np.random.default_rng(1)
    drive = d.add(PointToPoint(rng.uniform(0, 20, (5, 2, 2)), n=5, gain=1.5), name="drive")
    d.connect(fleet.pose, drive.pose)
    d.connect(drive.cmd, fleet.cmd)
    truth = av.simulate(d, t_final=3.0, dt=0.05, progress=False)
    w = av.edit(d, root=tmp_path)
    assert w.errors == []
    assert w.document["blocks"]["drive"]["gain"] == 1.5
    assert w.document["blocks"]["fleet"]["type"] == "vehicles.Unicycle"
    assert sorted(w.document["wires"]) == [["drive.cmd", "fleet.cmd"],
                                           ["fleet.pose", "drive.pose"]]
    assert w.diagram is not d
    mine = av.simulate(w.diagram, t_final=3.0, dt=0.05, progress=False)
    np.testing.assert_array_equal(mine["fleet.pose"], truth["fleet.pose"])


def test_a_diagram_with_code_in_it_is_refused_by_name(tmp_path):
    import avblocks as av
    from avblocks.blocks import Function
    d = av.Diagram()
    d.add(Function(lambda t, u: u, inputs={"u": (2,)}, outputs={"y": (2,)}), name="f")
    with pytest.raises(av.AvError) as e:
        av.edit(d, root=tmp_path)
    assert "'f'" in str(e.value)


def test_the_page_opens_what_av_edit_was_given(sent, tmp_path):
    import avblocks as av
    w = av.edit("swap", root=tmp_path)
    files = _ask(w, sent, "files")["result"]
    assert files["initial"] == {"builtin": "swap"}
    doc = {"name": "given", "parameters": {"agents": 2, "seed": 1},
           "blocks": {"g": {"type": "blocks.Gain", "k": 2.0}}, "wires": []}
    w = av.edit(doc, root=tmp_path)
    initial = _ask(w, sent, "files")["result"]["initial"]
    assert initial == {"current": True}
    loaded = _ask(w, sent, "load", **initial)["result"]
    assert loaded["document"] == doc and loaded["path"] is None
    w = av.edit(None, root=tmp_path)
    assert _ask(w, sent, "files")["result"]["initial"] is None
