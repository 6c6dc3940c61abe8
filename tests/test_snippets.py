"""The README's and the docs' Python snippets run exactly as written.

Every fenced ```python block of a Markdown file runs, in order, in one
namespace, in a fresh folder; a block right after a line
``<!-- no-test: why -->`` is skipped (for fragments, or what needs
hardware)."""

import importlib.util
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[1]
FILES = [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))


def _helpers():
    spec = importlib.util.spec_from_file_location("make_images",
                                                  ROOT / "docs" / "make_images.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_extraction_finds_blocks_and_honours_the_marker(tmp_path):
    md = tmp_path / "a.md"
    md.write_text("text\n```python\nx = 1\n```\n<!-- no-test: fragment -->\n"
                  "```python\nraise SystemExit\n```\n- item\n\n  ```python\n  y = x + 1\n"
                  "  ```\n```bash\nls\n```\n")
    blocks = _helpers().python_blocks(md)
    assert [c for _, c in blocks] == ["x = 1", "y = x + 1"]
    assert [ln for ln, _ in blocks] == [2, 11]
    assert _helpers().run_blocks(md, tmp_path)["y"] == 2


def _run_as_notebooks():
    """Pages that ``test_docs_site.py::test_tutorial_notebooks_execute`` runs top to
    bottom in a Jupyter kernel (the same snippets, in order, and their printed
    output checked), where that test can run; running them here too only took
    time (lab 7's page trains a policy: 30 s more)."""
    if any(importlib.util.find_spec(m) is None for m in ("jupytext", "nbclient",
                                                           "ipykernel")):
        return set()
    spec = importlib.util.spec_from_file_location("notebooks", ROOT / "docs" / "notebooks.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return {(ROOT / "docs" / page).resolve() for page in mod.PAGES}


#: pages with at least one snippet to run (the others only show commands)
RUNNABLE = [p for p in FILES if _helpers().python_blocks(p)
            and p.resolve() not in _run_as_notebooks()]


@pytest.mark.parametrize("path", RUNNABLE, ids=[p.name for p in RUNNABLE])
def test_markdown_python_snippets_run(path, tmp_path, monkeypatch):
    import matplotlib.pyplot as plt
    # small sizes, as the examples' test (lab 7's page loads a trained policy)
    monkeypatch.setenv("AVBLOCKS_EXAMPLE_SMALL", "1")
    h = _helpers()
    try:
        h.run_blocks(path, tmp_path)
    finally:
        plt.close("all")


def test_partial_snippets_compile():
    """A fence marked ``no-test`` (a fragment, or one that needs hardware) is
    still valid Python: it is parsed, just not run."""
    import ast
    h = _helpers()
    found = 0
    for path in FILES:
        for line, code in h.python_blocks(path, partial=True):
            found += 1
            try:
                ast.parse(code)
            except SyntaxError as e:
                raise AssertionError(f"{path.name}:{line}: {e}") from None
    assert found >= 1


@pytest.mark.slow
def test_readme_scales_to_30000_agents_by_changing_n_only(tmp_path):
    """README: "Going from 15 to 30,000 agents changes N, nothing else." The
    "Twenty lines" snippet with N = 30_000 and nothing else changed (2.2 GB
    of log at every step: the default cap decimates to every 2nd step)."""
    import re
    import warnings

    import numpy as np
    text = (ROOT / "README.md").read_text()
    assert "Going from 15 to 30,000 agents changes `N`, nothing else." in text
    code = next(c for _, c in _helpers().python_blocks(ROOT / "README.md")
                if "N = 300" in c)
    code = re.sub(r"^N = 300$", "N = 30_000", code, count=1, flags=re.M)
    code = code.replace('res.save("run.nc")', 'pass')   # 1 GB to disk: not what is tested
    ns = {}
    import os
    old = os.getcwd()
    os.chdir(tmp_path)
    try:
        with warnings.catch_warnings(record=True):
            warnings.simplefilter("always")
            exec(compile(code, "README.md", "exec"), ns)
    finally:
        os.chdir(old)
    pose = ns["res"][ns["fleet"].pose]
    assert pose.shape == (1501, 30_000, 3) and ns["res"].meta["log_every"] == 2
    assert np.isfinite(pose).all()
