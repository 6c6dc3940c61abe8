"""Every example runs (small sizes) and finishes without error."""

import os
import runpy
import sys
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).parent.parent / "examples").glob("[0-9]*.py"))


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_runs(path, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("AVBLOCKS_EXAMPLE_SMALL", "1")
    monkeypatch.setattr(sys, "argv", [str(path), "12"])
    runpy.run_path(str(path), run_name="__main__")
    assert os.getcwd() == str(tmp_path)
