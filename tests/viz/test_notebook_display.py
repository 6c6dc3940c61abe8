"""What a Jupyter user sees: a Diagram draws itself (SVG), Results show a
table (HTML), and simulate() shows a progress bar; checked in a real kernel."""

from __future__ import annotations

import importlib.util
import re

import numpy as np
import pytest

import avblocks as av


def _diagram(n=3):
    d = av.Diagram()
    fleet = d.add(av.vehicles.Unicycle(pose0=np.zeros((n, 3))), name="fleet")
    go = d.add(av.blocks.Constant(np.tile([1.0, 0.1], (n, 1))), name="go")
    d.connect(go.y, fleet.cmd)
    return d, fleet


def test_diagram_svg_names_every_block_and_wire():
    d, _ = _diagram()
    svg = d._repr_svg_()
    assert svg.lstrip().startswith("<?xml") and "<svg" in svg
    for name in ("fleet", "go", "Unicycle", "Constant", "cmd", "pose"):
        assert name in svg
    assert "wire go.y -&gt; fleet.cmd" in svg or "wire go.y -> fleet.cmd" in svg
    assert repr(d) == "<Diagram: 2 blocks, 1 wires (fleet: Unicycle, go: Constant)>"


def test_diagram_that_cannot_be_drawn_yet_falls_back_to_text():
    assert av.Diagram()._repr_svg_() is None
    d = av.Diagram()
    d.add(av.vehicles.Unicycle(pose0=np.zeros((2, 3))), name="fleet")   # cmd unwired
    out = d._repr_svg_()
    assert out is None or "<svg" in out


def test_results_html_lists_signals_shapes_span_and_status():
    d, fleet = _diagram(4)
    res = av.simulate(d, 1.0, dt=0.1, log=[fleet.pose], progress=False)
    page = res._repr_html_()
    assert "avblocks.Results" in page and "11 samples" in page
    assert "t = 0 .. 1 s" in page and "every 0.1 s" in page
    row = re.search(r"<tr><td[^>]*>fleet.pose</td><td[^>]*>\(4, 3\)</td>"
                    r"<td[^>]*>float64</td>", page)
    assert row, page
    x = res[fleet.pose]
    assert f"{x.min():.4g} .. {x.max():.4g}" in page
    assert "wall_time" in page


def test_results_html_escapes_and_shows_ensembles():
    t = np.linspace(0, 1, 3)
    res = av.Results(t, {"a<b>.y": np.zeros((5, 3, 2))}, runs=5)
    page = res._repr_html_()
    assert "a&lt;b&gt;.y" in page and "<b>.y" not in page
    assert "5 runs &times; 3 samples" in page and "(2,)" in page


def test_progress_default_off_outside_a_terminal_or_notebook(monkeypatch):
    from avblocks.core import runguard
    monkeypatch.setenv("CI", "1")
    assert runguard._progress_wanted(None) is False
    assert runguard._progress_wanted(True) is True
    assert runguard.in_notebook() is False


@pytest.mark.skipif(importlib.util.find_spec("nbclient") is None
                    or importlib.util.find_spec("ipykernel") is None,
                    reason="needs nbclient and ipykernel (the docs extra)")
def test_in_a_jupyter_kernel(tmp_path):
    import nbclient
    import nbformat
    from nbformat.v4 import new_code_cell, new_notebook
    setup = ("import os; os.environ.pop('CI', None)\n"
             "import numpy as np, avblocks as av\n"
             "d = av.Diagram()\n"
             "fleet = d.add(av.vehicles.Unicycle(pose0=np.zeros((3, 3))), name='fleet')\n"
             "go = d.add(av.blocks.Constant(np.tile([1.0, 0.1], (3, 1))), name='go')\n"
             "_ = d.connect(go.y, fleet.cmd)")
    nb = new_notebook(cells=[new_code_cell(setup), new_code_cell("d"),
                             new_code_cell("res = av.simulate(d, 2.0, dt=0.01, log=[fleet.pose])"
                                           "\nres")])
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3",
                                 "language": "python"}
    nbclient.NotebookClient(nb, timeout=300, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}}).execute()
    nbformat.validate(nb)
    shown = nb.cells[1].outputs[0]["data"]
    assert "image/svg+xml" in shown and "fleet" in shown["image/svg+xml"]
    outs = nb.cells[2].outputs
    result = [o for o in outs if o.get("output_type") == "execute_result"][0]["data"]
    assert "fleet.pose" in result["text/html"] and "(3, 3)" in result["text/html"]
    # the progress bar: a widget (ipywidgets) or tqdm's text bar on stderr
    bar = [o for o in outs if o.get("output_type") == "display_data"
           and "application/vnd.jupyter.widget-view+json" in o.get("data", {})]
    text = "".join(o.get("text", "") for o in outs if o.get("name") == "stderr")
    assert bar or "200/200" in text or "step" in text
