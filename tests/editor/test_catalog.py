"""The editor's palette comes from the blocks' own declarations: every
public block, ports equal to a built instance's, parameters as the
docstrings and declare_parameter state them, user modules as families."""

import json
import os
import sys
import textwrap

import numpy as np
import pytest

import avblocks as av
from avblocks import ScenarioError
from avblocks.core.declarations import doc_sections
from avblocks.editor.catalog import FAMILIES, _summary, build_template, palette, plain
from avblocks.scenarios import GENERATORS, Scenario, block_registry

REGISTRY = block_registry(interfaces=True)


@pytest.fixture(scope="module")
def pal():
    return palette()


def _needs_extra(typ, request):
    """The interface blocks' templates need MuJoCo/OpenCV (skip without
    them on a user's machine; fail in CI)."""
    if typ.startswith("interfaces."):
        request.getfixturevalue("mujoco_extra")


def _entries(pal):
    return {b["type"]: b for f in pal["families"] for b in f["blocks"]}


def test_every_public_block_is_in_the_palette_in_family_order(pal, request):
    json.dumps(pal)                                   # plain JSON
    entries = _entries(pal)
    assert set(entries) == set(REGISTRY)
    assert {"interfaces.mujoco.PhysicsWorld", "interfaces.vision.ColorBlobTracker"} <= set(entries)
    names = [f["name"] for f in pal["families"]]
    assert names == [f for f in FAMILIES if f in names]
    for f in pal["families"]:
        assert all(b["type"].startswith(f["name"] + ".") for b in f["blocks"])
    for typ, b in entries.items():
        if b["error"] and "optional extra" in b["error"]:
            _needs_extra(typ, request)
        assert b["error"] is None, (typ, b["error"])
        assert b["summary"] and b["doc"], typ
    assert {g["name"] for g in pal["generators"]} == set(GENERATORS)
    rp = next(g for g in pal["generators"] if g["name"] == "random_poses")
    assert [a["name"] for a in rp["args"]] == ["n", "area", "seed", "min_separation"]
    assert rp["args"][0]["required"] and not rp["args"][2]["required"]


@pytest.mark.parametrize("typ", sorted(REGISTRY))
def test_ports_equal_an_instance_built_from_the_template(pal, typ, request):
    """The template built with $agents = 7: names, dtypes, and shapes with
    the agent axis N = 7 (ports whose leading axis is not the agents' keep
    their numbers)."""
    _needs_extra(typ, request)
    b = _entries(pal)[typ]
    block = build_template(REGISTRY[typ], typ, b["template"], agents=7, seed=1)
    for side, ports in (("inputs", block._inputs), ("outputs", block._outputs)):
        assert [p["name"] for p in b[side]] == list(ports), (typ, side)
        for p in b[side]:
            q = ports[p["name"]]
            assert p["dtype"] == str(q.dtype)
            if q.shape is None:
                assert p["shape"] == "(any)"
                continue
            dims = p["shape"].strip("()").replace(" ", "").rstrip(",")
            dims = [7 if s == "N" else int(s) for s in dims.split(",")] if dims else []
            assert tuple(dims) == tuple(q.shape), (typ, p)


def test_a_template_builds_with_the_agent_count_it_is_given(pal):
    """$agents is what sizes a dragged block: 300 agents, 300 rows."""
    for typ in ("vehicles.Unicycle", "controllers.PointToPoint", "environment.Gossip"):
        b = _entries(pal)[typ]
        assert "$agents" in json.dumps(b["template"]) and b["ports_depend_on"]
        block = build_template(block_registry()[typ], typ, b["template"], agents=300)
        shapes = [p.shape for p in [*block._inputs.values(), *block._outputs.values()]
                  if p.shape]
        assert shapes and all(s[0] == 300 for s in shapes), typ


def _param(pal, typ, name):
    return next(p for p in _entries(pal)[typ]["params"] if p["name"] == name)


def test_parameters_as_the_docstrings_and_declarations_state_them(pal):
    # Unicycle: "pose0 : array_like, (N, 3)", required; v_max a numeric
    # parameter with bounds [0, inf] (its docstring says so) in m/s
    p = _param(pal, "vehicles.Unicycle", "pose0")
    assert (p["kind"], p["shape"], p["required"], p["numeric"]) == \
        ("per_agent", "(N, 3)", True, False)
    p = _param(pal, "vehicles.Unicycle", "v_max")
    assert p["numeric"] and p["bounds"] == [0, None] and p["unit"] == "m/s"
    assert p["shape"] == "(N,)" and p["default"] is None       # inf: no limit
    # PointToPoint: "gain : float or (N,)", default 1.0, a numeric parameter
    p = _param(pal, "controllers.PointToPoint", "gain")
    assert p["kind"] == "float" and p["default"] == 1.0 and p["numeric"]
    # Policy: '{"tanh", "relu", "elu"}' is a choice
    p = _param(pal, "controllers.Policy", "activation")
    assert p["kind"] == "choice" and p["choices"] == ["tanh", "relu", "elu"]
    assert p["default"] == "tanh"
    # Gossip: 'input : "pose" or "position"'; n an int, required
    p = _param(pal, "environment.Gossip", "input")
    assert p["kind"] == "choice" and p["choices"] == ["pose", "position"]
    p = _param(pal, "environment.Gossip", "n")
    assert p["kind"] == "int" and p["required"]
    # Flocking's h: "0 < h < 1" declared as open bounds just inside (0, 1)
    p = _param(pal, "controllers.Flocking", "h")
    assert p["numeric"] and 0 < p["bounds"][0] < 1e-6 and 1 - 1e-6 < p["bounds"][1] < 1
    # every documented argument's description is the docstring's
    for typ, b in _entries(pal).items():
        docs = doc_sections(REGISTRY[typ].__doc__).get("Parameters", {})
        for p in b["params"]:
            if p["name"] in docs and docs[p["name"]][1]:
                assert p["doc"] == plain(docs[p["name"]][1]), (typ, p["name"])


def test_palette_text_is_rendered_not_raw_restructuredtext(pal):
    """What the palette shows has no reStructuredText markup left: roles
    (``:class:`World```) are their target's name, literals single-backtick
    code (drawn as code by the page); docutils, a parser we did not write,
    reads each double-backtick text to the same characters."""
    import re
    gain = _entries(pal)["blocks.Gain"]
    assert gain["summary"].startswith("`y = k * u` (elementwise")
    assert "`World`" in _entries(pal)["environment.Collision"]["summary"]
    raw = re.compile(r":[a-z]+:`|``")
    texts = [(t, b["summary"]) for t, b in _entries(pal).items()]
    texts += [(t, r["doc"]) for t, b in _entries(pal).items()
              for r in [*b["params"], *b["inputs"], *b["outputs"]] if r["doc"]]
    assert len(texts) > 300
    for typ, text in texts:
        assert not raw.search(text), (typ, text)
    try:
        from docutils.core import publish_doctree
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip("needs docutils")
    checked = 0
    for typ, cls in REGISTRY.items():
        summary = _summary(cls)
        if "``" not in summary or re.search(r":[a-z]+:`", summary) or typ not in _entries(pal):
            continue
        tree = publish_doctree(summary, settings_overrides={"report_level": 5})
        assert tree.astext() == _entries(pal)[typ]["summary"].replace("`", ""), typ
        checked += 1
    assert checked >= 3


def test_a_user_module_is_a_family_of_its_own(tmp_path, monkeypatch):
    pkg = tmp_path / "mylab"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "blocks.py").write_text(textwrap.dedent('''
        import avblocks as av


        class Boost(av.Block):
            """Multiplies each agent's signal by a gain.

            Parameters
            ----------
            n : int
                Agents.
            gain : float
                The factor [1/s].
            mode : {"plain", "clipped"}
                How.
            """

            def __init__(self, n, gain=2.0, mode="plain"):
                super().__init__()
                self.n = n
                self.declare_input("u", (n, 2))
                self.declare_output("y", (n, 2))
                self.declare_parameter("gain", gain, bounds=(0, 10), unit="1/s")

            def output(self, t, x, u, xp):
                return {"y": self.gain * u["u"]}


        __all__ = ["Boost"]
    '''))
    monkeypatch.syspath_prepend(str(tmp_path))
    data = {"name": "lab", "parameters": {"agents": 4},
            "blocks": {"src": {"type": "blocks.Constant", "value": [[1.0, 2.0]] * 4},
                       "boost": {"type": "mylab.blocks.Boost", "n": "$agents",
                                 "gain": 3.0}},
            "wires": [["src.y", "boost.u"]], "simulation": {"t_final": 0.1}}
    try:
        pal = palette(extra_modules=("mylab.blocks",))
        with pytest.raises(ScenarioError, match="unknown block type 'mylab.blocks.Boost'"):
            Scenario(data, "<lab>").build(output_dir=tmp_path / "o")
        d, sim = Scenario(data, "<lab>", modules=("mylab.blocks",)).build(
            output_dir=tmp_path / "o")
        res = av.simulate(d, progress=False, **sim)
        assert np.allclose(res["boost.y"][-1], [[3.0, 6.0]] * 4)
    finally:
        sys.modules.pop("mylab.blocks", None)
        sys.modules.pop("mylab", None)
    fam = pal["families"][-1]
    assert fam["name"] == "mylab.blocks"
    (b,) = fam["blocks"]
    assert b["type"] == "mylab.blocks.Boost" and b["template"] == {"n": "$agents"}
    assert b["inputs"] == [{"name": "u", "shape": "(N, 2)", "dtype": "float64",
                            "unit": "", "doc": ""}]
    gain = next(p for p in b["params"] if p["name"] == "gain")
    assert gain["bounds"] == [0, 10] and gain["unit"] == "1/s" and gain["numeric"]
    mode = next(p for p in b["params"] if p["name"] == "mode")
    assert mode["choices"] == ["plain", "clipped"]
    assert np.isclose(gain["default"], 2.0)
