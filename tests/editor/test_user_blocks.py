"""Blocks from a user's module (``avblocks edit --blocks mylab2.blocks``):
palette, validation, a run and the exported script, end to end through the
editor's service."""

from __future__ import annotations

import runpy
import sys
import textwrap

import numpy as np
import pytest

from avblocks.editor.service import EditorService


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    pkg = tmp_path / "mylab2"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "blocks.py").write_text(textwrap.dedent('''
        import avblocks as av


        class Triple(av.Block):
            """Three times its input.

            Parameters
            ----------
            n : int
                Agents.
            """

            def __init__(self, n):
                super().__init__()
                self.declare_input("u", (n, 2))
                self.declare_output("y", (n, 2))

            def output(self, t, x, u, xp):
                return {"y": 3.0 * u["u"]}


        __all__ = ["Triple"]
    '''))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "mylab2.blocks"
    sys.modules.pop("mylab2.blocks", None)
    sys.modules.pop("mylab2", None)


def test_user_blocks_validate_run_and_export(tmp_path, user_module):
    doc = {"name": "lab", "parameters": {"agents": 3, "seed": 1},
           "blocks": {"src": {"type": "blocks.Constant", "value": [[1.0, 2.0]] * 3},
                      "x3": {"type": "mylab2.blocks.Triple", "n": "$agents"}},
           "wires": [["src.y", "x3.u"]],
           "simulation": {"t_final": 0.2, "dt": 0.1, "log": ["x3.y"]}}
    plain = EditorService(tmp_path)
    errs = plain.validate(doc)["errors"]
    assert [e["block"] for e in errs] == ["x3"] and "unknown block type" in errs[0]["message"]
    service = EditorService(tmp_path, extra_modules=[user_module])
    fams = [f["name"] for f in service.palette()["families"]]
    assert fams[-1] == user_module
    v = service.validate(doc)
    assert v["ok"], v["errors"]
    assert v["signals"]["x3.y"] == {"shape": "(3, 2)", "dtype": "float64"}
    rid = service.run(doc)["run"]
    st = service.wait(rid, 120)
    assert st["status"] == "done", st
    sig = service.signal(rid, "x3.y")
    np.testing.assert_allclose(np.asarray(sig["values"])[-1], [[3.0, 6.0]] * 3)
    text = service.export(doc)["text"]
    assert "from mylab2.blocks import Triple" in text
    (tmp_path / "lab.py").write_text(text)
    res = runpy.run_path(str(tmp_path / "lab.py"))["res"]
    np.testing.assert_allclose(res["x3.y"][-1], [[3.0, 6.0]] * 3)
