"""print(block) and repr(block) show its ports with their shapes; `avblocks
list --blocks` lists every public block with a one-line summary."""

import importlib
import inspect

import numpy as np

import avblocks as av
from avblocks.cli import main


def test_repr_and_str_show_ports_with_shapes():
    b = av.controllers.PointToPoint(np.zeros((3, 2, 2)))
    assert repr(b) == ("PointToPoint(in: [pose (3, 3)], out: [cmd (3, 2), target (3, 2), "
                       "arrived (3,), done (3,)])")
    text = str(b).splitlines()
    assert text[0] == "PointToPoint (continuous)"
    assert text[1].split() == ["in", "pose", "(3,", "3)", "[m,", "m,", "rad]"]
    assert ["out", "done", "(3,)", "bool"] in [ln.split() for ln in text]
    g = av.blocks.Gain(2.5)
    assert any(ln.split()[:3] == ["param", "k", "2.5"] for ln in str(g).splitlines())
    assert repr(av.viz.Scope("u")) == "Scope(in: [u (any)], out: [])"


def public_blocks():
    out = {}
    for fam in ("blocks", "vehicles", "controllers", "environment", "viz"):
        mod = importlib.import_module(f"avblocks.{fam}")
        for name in mod.__all__:
            obj = getattr(mod, name)
            if inspect.isclass(obj) and issubclass(obj, av.Block):
                out[f"{fam}.{name}"] = obj
    return out


def test_list_blocks_lists_every_public_block_with_its_summary(capsys):
    assert main(["list", "--blocks"]) == 0
    lines = {ln.split()[0]: ln.split(None, 1)[1] for ln in
             capsys.readouterr().out.splitlines() if ln.strip()}
    expected = public_blocks()
    assert {"viz.Scope", "blocks.Function", "viz.Animation2D"} <= set(expected)
    assert set(expected) <= set(lines)
    for k, cls in expected.items():
        first = " ".join(cls.__doc__.strip().split("\n\n")[0].split())
        assert first.startswith(lines[k].rstrip(".")), k
        assert 10 < len(lines[k]) < 200, k
