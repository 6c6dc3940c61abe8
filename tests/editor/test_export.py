"""The Python export: the exported script, RUN, gives the scenario's results."""

from __future__ import annotations

import runpy

import numpy as np
import pytest

from avblocks.editor.service import EditorService


@pytest.mark.parametrize("name,steps", [("formation", "t_final=4"), ("nest", "t_final=4"),
                                        ("flocking", "t_final=3"), ("swap", "t_final=3"),
                                        ("honeybee", "t_final=5"), ("pursuit", "t_final=3"),
                                        ("spread", "t_final=2"), ("navigation", "t_final=2")])
def test_exported_script_runs_to_the_scenario_results(tmp_path, name, steps):
    from avblocks.core.frontend import simulate
    from avblocks.scenarios.targets import load_any
    key, value = steps.split("=")
    service = EditorService(tmp_path)
    doc = service.load(builtin=name)["document"]
    doc["parameters"][key] = float(value)               # a short run of the same file
    text = service.export(doc, format="python")["text"]
    compile(text, "exported.py", "exec")
    assert "GENERATORS" in text and "av.simulate(" in text
    assert "$" not in text.split('"""', 2)[-1]             # references became variables
    script = tmp_path / "exported.py"
    script.write_text(text)
    ns = runpy.run_path(str(script), run_name="__main__")
    mine = ns["res"]
    # the scenario file run through the loader, as `avblocks run` does
    d, sim = load_any(name, {key: float(value)})[:2]
    truth = simulate(d, progress=False, **sim)
    assert sorted(mine.keys()) == sorted(truth.keys())
    np.testing.assert_array_equal(mine.t, truth.t)
    for k in truth.keys():
        np.testing.assert_array_equal(mine[k], truth[k], err_msg=k)


def test_export_refuses_an_invalid_diagram(tmp_path):
    from avblocks.editor.service import EditorError
    service = EditorService(tmp_path)
    doc = {"name": "x", "parameters": {"agents": 3, "seed": 1},
           "blocks": {"fleet": {"type": "vehicles.Unicycle",
                                "pose0": {"zeros": {"shape": [3, 3]}}}}, "wires": []}
    with pytest.raises(EditorError) as e:
        service.export(doc, format="python")
    assert e.value.errors[0]["port"] == "cmd"


def test_docs_page_is_the_protocol_file():
    from pathlib import Path
    root = Path(__file__).resolve().parents[2]
    api = (root / "src/avblocks/editor/API.md").read_text()
    page = (root / "docs/editor-api.md").read_text()
    assert page.endswith(api.split("\n", 1)[1])          # all but the title


def test_a_layout_only_edit_reuses_the_findings_a_real_edit_does_not(tmp_path):
    service = EditorService(tmp_path)
    doc = service.load(builtin="nest")["document"]
    e1, s1, b1 = service.check(doc)
    moved = dict(doc, editor={"layout": {"bees": [10, 20]}})
    e2, s2, b2 = service.check(moved)
    assert (e1, s1) == (e2, s2) == ([], s1) and b2 is b1       # remembered
    more = dict(moved, parameters={**doc["parameters"], "agents": 7})
    e3, s3, b3 = service.check(more)
    assert b3 is not b1 and s3["bees.pose"]["shape"] == "(7, 3)"
    assert service.check(doc, fresh=True)[2] is not b1
    e2.append("changed by a caller")                            # copies handed out
    assert service.check(moved)[0] == []


def test_a_function_block_named_by_import_path_is_no_unknown_type(tmp_path):
    """honeybee.yaml's scouts choose their command with a blocks.Function whose
    function the file names by import path: when another part of the document
    is wrong, the editor reports that part, not the Function block."""
    service = EditorService(tmp_path)
    doc = service.load(builtin="honeybee")["document"]
    assert service.validate(doc)["ok"]
    fn_blocks = [n for n, b in doc["blocks"].items() if b["type"] == "blocks.Function"]
    assert fn_blocks
    broken = dict(doc, wires=doc["wires"][1:])               # one input left undriven
    out = service.validate(broken)
    assert not out["ok"]
    dst = doc["wires"][0][1].partition(".")[0]
    assert any(e.get("block") == dst for e in out["errors"]), out["errors"]
    assert not any("unknown block type" in e["message"] for e in out["errors"]), out["errors"]
