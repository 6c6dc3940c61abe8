"""Diagram pictures: DOT text and the Matplotlib fallback."""

import re
import shutil
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import avblocks as av
import avblocks.viz as viz


class Ctrl(av.Block):
    def __init__(self, n):
        super().__init__()
        self.declare_input("pose", (n, 3))
        self.declare_input("goal", (n, 2))
        self.declare_output("cmd", (n, 2))

    def output(self, t, x, u, xp):
        return {"cmd": xp.zeros_like(u["goal"])}


def three_blocks(n=4):
    d = av.Diagram()
    g = d.add(av.blocks.Constant(np.zeros((n, 2))), name="goal")
    c = d.add(Ctrl(n), name="ctrl")
    f = d.add(av.vehicles.Unicycle(np.zeros((n, 3))), name="fleet")
    d.connect(g.y, c.goal)
    d.connect(c.cmd, f.cmd)
    d.connect(f.pose, c.pose)
    return d


WIRES = {("goal", "y", "ctrl", "goal"), ("ctrl", "cmd", "fleet", "cmd"),
         ("fleet", "pose", "ctrl", "pose")}


def test_dot_text_has_blocks_ports_and_wires():
    dot = viz.to_dot(three_blocks())
    for name in ("goal", "ctrl", "fleet"):
        assert f'"{name}" [label=<' in dot
    assert 'PORT="i_pose"' in dot and 'PORT="o_cmd"' in dot
    found = set(re.findall(r'"(\w+)":"o_(\w+)":e -> "(\w+)":"i_(\w+)":w', dot))
    assert found == WIRES
    assert '"fleet":"o_pose":e -> "ctrl":"i_pose":w [label="(4, 3)"]' in dot
    assert dot.count("{") == dot.count("}")


def test_to_graphviz_method_uses_to_dot():
    d = three_blocks()
    assert d.to_graphviz() == viz.to_dot(d)


def test_subsystem_is_a_cluster():
    d = three_blocks()
    sub = av.Diagram()
    k = sub.add(av.blocks.Gain(2.0), name="k")
    sub.export_input("u", k.u)
    sub.export_output("y", k.y)
    h = d.add(sub, name="filt")
    d.connect(d["fleet"].pose, h.u)
    dot = viz.to_dot(d)
    assert 'subgraph "cluster_filt"' in dot
    assert '"fleet":"o_pose":e -> "filt.@in.u"' in dot
    assert '"filt.@in.u" -> "filt.k":"i_u":w [label="(4, 3)"]' in dot


def test_matplotlib_svg_has_names_and_wires(tmp_path):
    path = viz.draw_diagram(three_blocks(), tmp_path / "d.svg", engine="matplotlib")
    root = ET.parse(path).getroot()
    texts = {"".join(e.itertext()).strip() for e in root.iter() if e.tag.endswith("text")}
    assert {"goal", "ctrl", "fleet"} <= texts
    assert {"pose", "cmd", "(4, 3)", "(4, 2)"} <= texts
    ids = {e.get("id") for e in root.iter() if (e.get("id") or "").startswith("wire ")}
    assert ids == {f"wire {a}.{b} -> {c}.{d}" for a, b, c, d in WIRES}


def test_png_fallback(tmp_path):
    path = viz.draw_diagram(three_blocks(), tmp_path / "d.png", engine="matplotlib")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.skipif(shutil.which("dot") is None, reason="Graphviz dot not installed")
def test_graphviz_svg(tmp_path):
    path = viz.draw_diagram(three_blocks(), tmp_path / "g.svg", engine="dot")
    svg = path.read_text()
    for name in ("goal", "ctrl", "fleet"):
        assert f">{name}<" in svg
    assert svg.count('class="edge"') == 3


def test_bad_format():
    with pytest.raises(av.ParameterError, match="unknown picture format"):
        viz.draw_diagram(three_blocks(), "d.jpg")


@pytest.mark.parametrize("name", ["formation", "honeybee"])
def test_matplotlib_wires_go_around_the_blocks_they_skip(name):
    """A wire that skips a column passes through the gaps between that
    column's blocks: no point of any wire lies inside a block other than
    its own two ends (formation's fleet.pose -> lf.pose crossed the
    collision block's title)."""
    from avblocks.scenarios.loader import load_scenario
    from avblocks.viz.diagram import draw_diagram_matplotlib

    d = load_scenario(name).build()[0]
    fig = draw_diagram_matplotlib(d)
    ax = fig.axes[0]
    boxes = {}
    for p in ax.patches:
        gid = p.get_gid() or ""
        if gid.startswith("block "):
            bb = p.get_bbox()
            boxes[gid[6:]] = (bb.x0, bb.y0, bb.x1, bb.y1)
    wires = [p for p in ax.patches if (p.get_gid() or "").startswith("wire ")]
    assert len(boxes) >= 6
    assert wires
    for w in wires:
        src, dst = re.match(r"wire (.+)\.\w+ -> (.+)\.\w+", w.get_gid()).groups()
        # the patch's own path in data coordinates, curves sampled finely
        pts = np.concatenate([seg(np.linspace(0, 1, 50))
                              for seg, _ in w.get_path().iter_bezier()])
        for blk, (x0, y0, x1, y1) in boxes.items():
            if blk in (src, dst):
                continue
            inside = ((pts[:, 0] > x0 + 0.05) & (pts[:, 0] < x1 - 0.05)
                      & (pts[:, 1] > y0 + 0.05) & (pts[:, 1] < y1 - 0.05))
            assert not inside.any(), f"{w.get_gid()} crosses block {blk}"
