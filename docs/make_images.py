"""Regenerate the README's scenario pictures from the scenarios themselves.

    python docs/make_images.py            # every built-in scenario
    python docs/make_images.py nest swap  # some

Each picture is exactly the figure ``avblocks run NAME`` writes (the
scenario's own ``figures``), copied to ``docs/images/scenario_NAME.png``.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

from avblocks.cli import main
from avblocks.scenarios import builtin_scenarios

IMAGES = Path(__file__).resolve().parent / "images"


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
    for n in sys.argv[1:] or list(builtin_scenarios()):
        make(n)
