"""Regenerate the README's scenario pictures from the scenarios themselves,
and the pictures of docs/plots-and-movies.md from its own snippets.

    python docs/make_images.py            # every built-in scenario
    python docs/make_images.py nest swap  # some
    python docs/make_images.py --docs     # run plots-and-movies.md's snippets

Each picture is exactly the figure ``avblocks run NAME`` writes (the
scenario's own ``figures``), copied to ``docs/images/scenario_NAME.png``.
"""

from __future__ import annotations

import os
import re
import shutil
import sys
import tempfile
from pathlib import Path

from avblocks.cli import main
from avblocks.scenarios import builtin_scenarios

DOCS = Path(__file__).resolve().parent
IMAGES = DOCS / "images"

_FENCE = re.compile(r"^(?P<indent>[ ]*)```python[ ]*\n(?P<code>.*?)^(?P=indent)```[ ]*$",
                    re.S | re.M)
_SKIP = re.compile(r"<!--\s*no-test\b[^>]*-->\s*$")


def python_blocks(path):
    """``[(line, code)]`` of the fenced ```python blocks of a Markdown file,
    in order, without those right after a ``<!-- no-test: why -->`` line."""
    text = Path(path).read_text()
    out = []
    for m in _FENCE.finditer(text):
        before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        if _SKIP.search(before):
            continue
        ind = len(m.group("indent"))
        code = "\n".join(ln[ind:] for ln in m.group("code").splitlines())
        out.append((text.count("\n", 0, m.start()) + 1, code))
    return out


def run_blocks(path, cwd):
    """Run a Markdown file's Python blocks in order, in one namespace, in
    the folder ``cwd``; returns the namespace."""
    ns = {"__name__": "__snippets__"}
    old = os.getcwd()
    os.chdir(cwd)
    try:
        for line, code in python_blocks(path):
            exec(compile(code, f"{path}:{line}", "exec"), ns)
    finally:
        os.chdir(old)
    return ns


def make(name: str) -> Path:
    with tempfile.TemporaryDirectory() as tmp:
        rc = main(["run", name, "--out", tmp, "--quiet"])
        if rc != 0:
            raise SystemExit(f"avblocks run {name} failed ({rc})")
        src = Path(tmp) / f"{name}.png"
        if not src.is_file():
            raise SystemExit(f"scenario {name} wrote no {name}.png")
        dst = IMAGES / f"scenario_{name}.png"
        shutil.copyfile(src, dst)
    print(f"wrote {dst}")
    return dst


if __name__ == "__main__":
    if sys.argv[1:] == ["--docs"]:
        import matplotlib
        matplotlib.use("Agg")
        run_blocks(DOCS / "plots-and-movies.md", IMAGES)
        (IMAGES / "run.gif").unlink(missing_ok=True)
        print(f"wrote the pictures of plots-and-movies.md into {IMAGES}")
    else:
        for n in sys.argv[1:] or list(builtin_scenarios()):
            make(n)
