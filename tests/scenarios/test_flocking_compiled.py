"""`avblocks run flocking --backend jax` gives the NumPy run's summary."""

import json

import pytest

from avblocks.cli import main

pytest.importorskip("jax")


def _numbers(tmp_path, *extra):
    rc = main(["run", "flocking", "--set", "simulation.t_final=20", "--out",
               str(tmp_path), "--quiet", *extra])
    assert rc == 0
    return json.loads((tmp_path / "summary.json").read_text())


def test_flocking_compiles_with_the_numpy_summary(tmp_path):
    a = _numbers(tmp_path / "numpy")
    b = _numbers(tmp_path / "jax", "--backend", "jax")
    assert a["agents"] == b["agents"] == 50 and a["status"] == b["status"]
    assert a["outcome"] == b["outcome"]
    for key, va in a["numbers"].items():
        vb = b["numbers"][key]
        if isinstance(va, int):
            assert va == vb, key
        else:
            assert vb == pytest.approx(va, rel=1e-4, abs=1e-12), key
