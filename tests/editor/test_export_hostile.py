"""The Python export under hostile names (issue 42): whatever a document's
texts hold, the exported script parses, runs no code but the diagram's, and
builds the same diagram as the scenario loader builds from the document.

The truth is the loader: the document built by
:meth:`avblocks.scenarios.Scenario.build` and simulated, against the script
run by ``runpy`` (block names and types, every numeric parameter, the
wiring, a Scope's options, a port's unit, and the logged results bit for
bit). Python's own parser (``ast.parse``) judges the script's text.
"""

from __future__ import annotations

import ast
import os
import runpy
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from avblocks.core.frontend import simulate
from avblocks.editor.export import to_python
from avblocks.scenarios import Scenario

INJECT = 'x"""\nimport os; open("pwned", "w").write("1")\n"""'
#: texts that have broken or could break a script's text: the issue's
#: injection, backslashes, every kind of quote, newlines, NUL, unicode,
#: a very long text, keywords and names the script itself uses
HOSTILE = [
    INJECT, "x'''\nimport os; open('pwned', 'w').write('1')\n'''",
    "C:\\Users", "run\\N", "\\", "\\\\", "'", '"', "'''", '"""', "`", "\\'", '\\"',
    '"); open("pwned", "w").write("1"); ("', "'); open('pwned', 'w').write('1'); ('",
    "\\'); open('pwned', 'w').write('1'); ('", "# c\nopen('pwned', 'w')",
    "a\nb", "a\r\nb", "\r", "\x00", "\u2028", "\u202e", "é", "\ufb01", "\U0001f600",
    "{x}", "%s", "$n", "${n}", "x" * 1000, "class", "None", "match", "_", "print",
    "__import__", "av", "diagram", "res", "GENERATORS", "1abc", "a-b", "a b", "", " ",
]
#: hostile texts that are identifiers (block and port names must be):
#: keywords, soft keywords, builtins, the script's own names, class names,
#: names Python folds together (NFKC: "\ufb01" is "fi" as a name), long ones
NAMES = ["class", "None", "match", "_", "print", "__import__", "av", "diagram", "res",
         "GENERATORS", "Unicycle", "Constant", "Scope", "Gain", "add", "port", "p_n",
         "b_fleet", "\ufb01", "\u00e9", "x" * 1000, "fleet_"]


def document(text="tiny", name="src", port="u"):
    """A small valid document carrying ``text`` everywhere a text may go and
    ``name`` as a block name and a Scope port name."""
    other = "\ufb01" if port == "fi" else "fi"
    return {
        "name": text,
        "description": text,
        "parameters": {"n": 2, "g": 2.0, "u": text, text: 1.0},
        "blocks": {
            name: {"type": "blocks.Constant", "unit": "$u",
                   "value": {"tile": {"value": [1.0, 0.0], "n": "$n"}}},
            "gain": {"type": "blocks.Gain",
                     "k": {"item": {"values": [text, "$g"], "index": 1}}},
            "fleet": {"type": "vehicles.Unicycle", "pose0": {"zeros": {"shape": ["$n", 3]}}},
            "scope": {"type": "viz.Scope", "inputs": [port, other], "title": text},
        },
        "wires": [[f"{name}.y", "gain.u"], ["gain.y", "fleet.cmd"],
                  ["fleet.pose", f"scope.{port}"], ["fleet.pose", f"scope.{other}"]],
        "simulation": {"t_final": 0.3, "dt": 0.1, "log": ["fleet.pose", f"{name}.y"]},
        "params": {"gain.k": 1.5},
    }


def _wiring(d):
    return {dst.path: src.path for dst, src in d._driver.items()}


def check_export(doc, folder):
    """Export ``doc``, run the script in ``folder`` and compare with the
    loader's build of ``doc``."""
    text = to_python(doc)
    tree = ast.parse(text)                            # Python's parser accepts it
    # every name of the script is ASCII (Python folds other names: NFKC)
    for node in ast.walk(tree):
        for ident in (getattr(node, "id", None), getattr(node, "attr", None),
                      getattr(node, "arg", None), getattr(node, "asname", None)):
            assert ident is None or ident.isascii(), ident
    script = Path(folder) / "exported.py"
    script.write_text(text, encoding="utf-8")
    before = set(os.listdir(folder))
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        ns = runpy.run_path(str(script), run_name="__main__")
    finally:
        os.chdir(cwd)
    assert set(os.listdir(folder)) == before          # no stray file
    assert not Path(cwd, "pwned").exists()
    mine, res = ns["diagram"], ns["res"]
    truth, sim = Scenario(doc, str(Path(folder) / "doc.yaml")).build(
        output_dir=Path(folder) / "out")
    assert mine.name == truth.name == doc["name"]
    assert list(mine.blocks) == list(truth.blocks)
    for n in truth.blocks:
        assert type(mine[n].block) is type(truth[n].block)
    assert _wiring(mine) == _wiring(truth)
    cm, ct = mine.build(), truth.build()
    pm, pt = cm.param_values(), ct.param_values()
    assert sorted(pm) == sorted(pt)
    for k in pt:
        np.testing.assert_array_equal(pm[k], pt[k], err_msg=k)
    for n, h in truth.blocks.items():
        if type(h.block).__name__ == "Scope":
            assert mine[n].block.plot_options == h.block.plot_options
            assert mine[n].block.names == h.block.names
        for port, spec in h.block.output_ports.items():
            assert mine[n].block.output_ports[port] == spec
    ref = simulate(truth, progress=False, **sim)
    assert sorted(res.keys()) == sorted(ref.keys())
    np.testing.assert_array_equal(res.t, ref.t)
    for k in ref.keys():
        np.testing.assert_array_equal(res[k], ref[k], err_msg=k)
    return text


@pytest.mark.parametrize("text", HOSTILE, ids=[repr(t)[:24] for t in HOSTILE])
def test_hostile_texts_export_to_the_same_diagram(tmp_path, text):
    body = check_export(document(text), tmp_path)
    if text == INJECT:
        # the name is a literal: the injected line is no statement of the script
        tree = ast.parse(body)
        assert not any(isinstance(n, ast.Import) and n.names[0].name == "os"
                       for n in ast.walk(tree))


def test_a_text_as_long_as_the_limit(tmp_path):
    doc = document("tiny")
    long = "\\'\"" * 25_000                  # 100,000 characters, the loader's limit
    doc["description"] = doc["name"] = doc["parameters"]["u"] = long
    doc["blocks"]["scope"]["title"] = long
    check_export(doc, tmp_path)


@pytest.mark.parametrize("name", NAMES, ids=[n[:12] for n in NAMES])
def test_hostile_block_and_port_names_export_to_the_same_diagram(tmp_path, name):
    check_export(document("tiny", name=name, port=name), tmp_path)


def test_names_python_folds_together_stay_apart(tmp_path):
    """"\ufb01" and "fi" are two block names and two Scope ports; as Python
    names they would be one (NFKC), so the script names them apart."""
    doc = document("tiny", name="\ufb01", port="\ufb01")
    doc["blocks"]["fi"] = dict(doc["blocks"].pop("gain"))
    doc["wires"] = [["\ufb01.y", "fi.u"], ["fi.y", "fleet.cmd"],
                    ["fleet.pose", "scope.\ufb01"], ["fleet.pose", "scope.fi"]]
    doc["params"] = {"fi.k": 1.5}
    doc["parameters"]["\ufb01"] = 5.0
    doc["parameters"]["fi"] = 6.0
    check_export(doc, tmp_path)


def test_texts_that_no_loader_accepts_still_export_as_literals(tmp_path):
    """Generator argument names, block arguments, function references and
    wire ends the loader would refuse: to_python writes them as literals or
    refuses them; the script parses and running it writes nothing."""
    from avblocks.core.errors import ScenarioError
    doc = document("tiny")
    doc["blocks"]["scope"][INJECT] = 1
    doc["blocks"]["gain"]["k"] = {"item": {INJECT: 1, "values": [1.0], "index": 0}}
    doc["params"] = {INJECT: 1.0}
    doc["simulation"]["solver"] = INJECT
    text = to_python(doc)
    tree = ast.parse(text)
    assert not any(isinstance(n, ast.Import) and n.names[0].name == "os"
                   for n in ast.walk(tree))
    (tmp_path / "bad.py").write_text(text)
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        with pytest.raises(Exception):          # the Scope refuses the option  # noqa: B017
            runpy.run_path(str(tmp_path / "bad.py"))
    finally:
        os.chdir(cwd)
    assert sorted(os.listdir(tmp_path)) == ["bad.py"]
    for ref in ("os:system", "avblocks.x:y\nimport os", "avblocks:_private", 'a"b:c'):
        bad = document("tiny")
        bad["blocks"]["gain"]["k"] = {"function": ref}
        with pytest.raises(ScenarioError):
            to_python(bad)
    bad = document("tiny")
    bad["blocks"]["x"] = {"type": INJECT}
    with pytest.raises(ScenarioError, match="unknown block type"):
        to_python(bad)


def test_the_editor_exports_a_hostile_name(tmp_path):
    """Through the editor's service, which validates first."""
    from avblocks.editor.service import EditorService
    text = EditorService(tmp_path).export(document(INJECT), format="python")["text"]
    assert ast.parse(text)
    assert text.splitlines()[0].startswith(("'''", '"""'))


_TEXT = st.text(st.characters(blacklist_categories=("Cs",)), max_size=40)
_NAME = st.text(st.characters(whitelist_categories=("Lu", "Ll", "Lo", "Nd", "Pc")),
                min_size=1, max_size=12).filter(str.isidentifier)


@settings(max_examples=15, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(text=_TEXT, name=_NAME)
def test_fuzz_texts_and_names_export_to_the_same_diagram(tmp_path_factory, text, name):
    if name in ("gain", "fleet", "scope"):
        name += "_"
    port = name if name != "fi" else "x_fi"
    check_export(document(text, name=name, port=port), tmp_path_factory.mktemp("x"))
