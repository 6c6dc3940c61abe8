"""Refresh ``tests/durations.json``: the longest tests' seconds, which
``tests/conftest.py`` uses to start the longest tests first.

Usage::

    .venv/bin/python -m pytest -n 3 -q --durations=0 > run.log
    .venv/bin/python tests/_durations.py run.log

Only the order of the run depends on these figures (the longest first, so
that no worker is left with a long test while the others are idle at the
end); a stale or missing file changes no result.
"""

from __future__ import annotations

import json
import re
import sys
from collections import defaultdict
from pathlib import Path

#: Tests shorter than this [s] keep their collection order.
MIN_SECONDS = 3.0
LINE = re.compile(r"^(\d+(?:\.\d+)?)s (?:call|setup|teardown)\s+(\S.*)$")


def parse(text):
    """Seconds per test id (setup + call + teardown) of ``--durations`` lines."""
    out = defaultdict(float)
    for line in text.splitlines():
        m = LINE.match(line.strip())
        if m:
            out[m.group(2).strip()] += float(m.group(1))
    return dict(out)


def main(argv):
    secs = parse(Path(argv[1]).read_text(errors="replace"))
    keep = {k: round(v, 1) for k, v in sorted(secs.items(), key=lambda kv: -kv[1])
            if v >= MIN_SECONDS}
    dest = Path(__file__).with_name("durations.json")
    dest.write_text(json.dumps(keep, indent=0, ensure_ascii=True) + "\n")
    print(f"{len(keep)} tests of at least {MIN_SECONDS:g} s ({sum(keep.values()):.0f} s) "
          f"-> {dest}")


if __name__ == "__main__":
    main(sys.argv)
