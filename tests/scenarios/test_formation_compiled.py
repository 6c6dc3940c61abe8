"""`avblocks run formation --backend jax` prints the NumPy run's outcome
numbers: integers and strings equal, floats within 1e-4 relative (or 1e-9
absolute for the ~1e-14 m formation errors, which are rounding noise).
Run with the default bodies (no contact; the full run, slow) and with
bodies large enough to touch the corridor walls and each other for the
first 50 s (Collision's counts are non-zero)."""

import json

import pytest

from avblocks.cli import main


def numbers(tmp_path, backend, *sets):
    out = tmp_path / backend
    args = ["run", "formation", "--backend", backend, "--out", str(out), "--quiet",
            "--set", "dt=0.05", "--set", "log_every=2"]
    for s in sets:
        args += ["--set", s]
    assert main(args) == 0
    return json.loads((out / "summary.json").read_text())["numbers"]


def same(a, b, where=""):
    if isinstance(a, list):
        assert len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b)):
            same(x, y, f"{where}[{k}]")
    elif isinstance(a, (int, str)):
        assert a == b, where
    else:
        assert b == pytest.approx(a, rel=1e-4, abs=1e-9), where


@pytest.mark.jax
@pytest.mark.parametrize("sets", [pytest.param((), marks=pytest.mark.slow),
                                  ("body_radius=1.05", "t_final=50")])
def test_formation_jax_summary_equals_numpy(tmp_path, sets):
    pytest.importorskip("jax")
    a = numbers(tmp_path, "numpy", *sets)
    b = numbers(tmp_path, "jax", *sets)
    assert a.keys() == b.keys()
    for k in a:
        same(a[k], b[k], k)
    if sets:
        assert a["states"] == ["wedge", "column"]
        assert a["samples_touching_wall"] > 100 and a["samples_touching_agent"] > 100
    else:
        assert a["samples_touching_wall"] == a["samples_touching_agent"] == 0
