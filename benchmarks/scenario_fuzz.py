"""How ``avblocks run`` answers hostile scenario files: counts, not times.

Two sets of files, both from ``tests/hardening/test_scenario_files.py``:

- the hand-written hostile shapes (``hostile_cases``: deep nesting in every
  section, through anchors, alias bombs, huge numbers and strings, huge
  files, TOML, FIFOs and devices), each run as ``python -m avblocks run`` in
  its own process with a 60 s timeout and a 4 GiB address-space limit;
- ``--random N`` files (default 300) with one random shape (deep list or
  mapping of a random depth up to 20,000, block-style nesting, an anchor
  chain, a long number, a long string) placed in a random section, run
  in-process through ``avblocks.cli.main`` (seeded: the same files each time).

Each answer is one of: ``ran`` (exit 0), ``clean`` (exit 2 or 3 with one
``avblocks: error:`` line per problem and no traceback), ``traceback`` (an
exception escaped, or a traceback was printed), ``timeout``, ``killed``
(a signal, e.g. out of memory).

Run: ``python benchmarks/scenario_fuzz.py [--random N] [--skip-hand]``;
prints a markdown table per set and the cases that were not clean. The
avblocks measured is the one on ``PYTHONPATH`` (default: this checkout's).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _cases_module():
    spec = importlib.util.spec_from_file_location(
        "scenario_file_cases", ROOT / "tests" / "hardening" / "test_scenario_files.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _classify(rc, err, escaped=False):
    if escaped or "Traceback" in err:
        return "traceback"
    if rc == 0:
        return "ran"
    if rc in (2, 3) and err.startswith("avblocks: error: "):
        return "clean"
    if rc == "timeout":
        return "timeout"
    if isinstance(rc, int) and rc < 0:
        return "killed"
    return "traceback"


def _limit_memory():
    import resource
    resource.setrlimit(resource.RLIMIT_AS, (4 * 1024**3, 4 * 1024**3))


def run_hand(mod):
    rows = []
    for case in mod.hostile_cases():
        with tempfile.TemporaryDirectory() as tmp:
            p = mod.make_hostile(tmp, case)
            t0 = time.perf_counter()
            env = {**os.environ, "MPLBACKEND": "Agg",
                   "PYTHONPATH": os.environ.get("PYTHONPATH") or str(ROOT / "src")}
            try:
                r = subprocess.run([sys.executable, "-m", "avblocks", "run", str(p),
                                    "--quiet", "--out", str(Path(tmp) / "out"),
                                    "--t-final", "0.2"], capture_output=True, text=True,
                                   timeout=60, env=env, preexec_fn=_limit_memory,
                                   errors="replace")
                rc, err = r.returncode, r.stderr
            except subprocess.TimeoutExpired:
                rc, err = "timeout", ""
            rows.append((case[0], _classify(rc, err), time.perf_counter() - t0,
                         err.strip().splitlines()[-1][:160] if err.strip() else ""))
    return rows


SHAPES = ["deep list", "deep mapping", "block style", "anchor chain", "long number",
          "long string"]


def random_file(mod, rng):
    """One random hostile file's text and its label."""
    shape = rng.choice(SHAPES)
    depth = int(10 ** rng.uniform(0.5, 4.3))
    section = rng.choice(mod.SECTIONS + ["block value"])
    if shape == "deep list":
        value = mod._deep_list(depth)
    elif shape == "deep mapping":
        value = mod._deep_map(depth)
    elif shape == "long number":
        value = "9" * depth
    elif shape == "long string":
        value = "x" * depth * 100
    else:
        value = None
    if shape == "block style":
        return mod._block_style(depth), f"{shape} {depth}"
    if shape == "anchor chain":
        return mod._anchor_chain(depth), f"{shape} {depth}"
    if section == "block value":
        return mod._with_block(value), f"{shape} {depth} in a block"
    return mod._in_section(section, value), f"{shape} {depth} in {section}"


def run_random(mod, n, seed=0):
    from avblocks.cli import main
    rng = random.Random(seed)
    rows = []
    for _ in range(n):
        text, label = random_file(mod, rng)
        with tempfile.TemporaryDirectory() as tmp:
            p = Path(tmp) / "s.yaml"
            p.write_text(text)
            out, err = io.StringIO(), io.StringIO()
            escaped = False
            t0 = time.perf_counter()
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                try:
                    rc = main(["run", str(p), "--quiet", "--out", str(Path(tmp) / "o"),
                               "--t-final", "0.2"])
                except BaseException as e:  # noqa: BLE001 - counted
                    rc, escaped = 1, True
                    err.write(f"Traceback: {type(e).__name__}: {str(e)[:100]}\n")
            rows.append((label, _classify(rc, err.getvalue(), escaped),
                         time.perf_counter() - t0,
                         err.getvalue().strip().splitlines()[-1][:160]
                         if err.getvalue().strip() else ""))
    return rows


def table(title, rows):
    kinds = ["ran", "clean", "traceback", "timeout", "killed"]
    counts = {k: sum(r[1] == k for r in rows) for k in kinds}
    print(f"\n### {title}\n")
    print("| tried | " + " | ".join(kinds) + " | slowest [s] |")
    print("|---|" + "---|" * len(kinds) + "---|")
    slow = max((r[2] for r in rows), default=0.0)
    print(f"| {len(rows)} | " + " | ".join(str(counts[k]) for k in kinds)
          + f" | {slow:.1f} |")
    bad = [r for r in rows if r[1] not in ("ran", "clean")]
    if bad:
        print("\nnot clean:\n")
        for name, kind, t, last in bad:
            print(f"- {name}: {kind} ({t:.1f} s) {last}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--random", type=int, default=300)
    ap.add_argument("--skip-hand", action="store_true")
    args = ap.parse_args()
    os.environ.setdefault("MPLBACKEND", "Agg")
    mod = _cases_module()
    if not args.skip_hand:
        table("hand-written hostile shapes (`avblocks run`, one process each)",
              run_hand(mod))
    if args.random:
        table(f"{args.random} random hostile files (in-process `avblocks.cli.main`)",
              run_random(mod, args.random))


if __name__ == "__main__":
    main()
