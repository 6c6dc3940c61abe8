"""Regenerate every outcome number the README and the docs quote, and every
case-study figure in ``docs/images``, from the runs themselves.

    python docs/regenerate.py                # run every case study, rewrite numbers and figures
    python docs/regenerate.py nest honeybee  # only these case studies
    python docs/regenerate.py --check        # change nothing; list what differs (exit 1 if any)
    python docs/regenerate.py --list         # the numbers the pages quote, by key

Each case study of :data:`CASES` runs as ``avblocks run NAME --out DIR
--quiet`` at its documented settings. Its ``summary.json`` gives the
numbers: ``NAME.outcome`` (the one-line outcome) and ``NAME.KEY`` for each
entry of its ``numbers``; its own figure (``NAME.png``) is the picture
``docs/images/scenario_NAME.png``.

A page quotes a number between two markers, with the format it is written
in (a Python format string; ``{}`` when left out)::

    all 500 informed at <!-- number: nest.all_informed_at_s {:.1f} s -->94.8 s<!-- /number -->

The text between the markers is what this script writes; the markers are
HTML comments, invisible on GitHub and in the site. ``--check`` (what
``tests/docs/test_regenerate.py`` runs in CI) compares the quoted text with
what the runs print now, character for character, and the committed
figures with the new ones by content: both are reduced to grey levels and
cut into 8 x 8 pixel tiles, and a figure differs when the mean absolute
difference of any tile exceeds :data:`TILE_TOLERANCE`, or when its size
differs. Measured: a changed number in a figure's title moves a tile by
0.41; a grain of 2 % grey on every pixel by 0.012; the committed waypoints
figure against a run on another day by 0.0004. A figure within tolerance
is not rewritten (no churn of committed bytes).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
IMAGES = DOCS / "images"

#: the case studies whose numbers and figures the pages show, with the
#: ``avblocks run`` options of their documented settings (none: defaults)
CASES: dict[str, list[str]] = {
    "waypoints": [],
    "nest": [],
    "honeybee": [],
    "formation": [],
    "flocking": [],
    "swap": [],
    "navigation": [],
    "spread": [],
    "pursuit": [],
}

#: largest mean absolute grey-level difference (0..1) of an 8 x 8 tile
TILE_TOLERANCE = 0.05
TILE = 8

_MARK = re.compile(r"<!-- number: (?P<key>[\w.]+)(?: (?P<fmt>[^>]*?))? -->"
                   r"(?P<text>.*?)<!-- /number -->", re.S)


def pages() -> list[Path]:
    """The pages that may quote numbers: the README and every docs page."""
    return [ROOT / "README.md", *sorted(p for p in DOCS.rglob("*.md")
                                        if "api" not in p.relative_to(DOCS).parts)]


def quoted(paths=None) -> list[tuple[Path, str, str, str]]:
    """``[(page, key, format, text)]`` for every marker of the pages."""
    out = []
    for page in paths or pages():
        for m in _MARK.finditer(page.read_text()):
            out.append((page, m.group("key"), m.group("fmt") or "{}", m.group("text")))
    return out


def run_case(name: str, out: Path) -> dict:
    """Run one case study into ``out/NAME``; its ``summary.json`` as a dict."""
    folder = out / name
    cmd = [sys.executable, "-m", "avblocks", "run", name, "--out", str(folder), "--quiet",
           *CASES[name]]
    env = {**os.environ, "MPLBACKEND": "Agg"}
    r = subprocess.run(cmd, cwd=out, env=env, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"avblocks run {name} exited {r.returncode}:\n{r.stderr[-2000:]}")
    summary = json.loads((folder / "summary.json").read_text())
    if summary.get("status") != "complete":
        raise RuntimeError(f"avblocks run {name}: status {summary.get('status')}")
    return summary


def values_of(summaries: dict[str, dict]) -> dict[str, object]:
    """``{"NAME.outcome": ..., "NAME.KEY": ...}`` from the runs' summaries."""
    vals = {}
    for name, s in summaries.items():
        vals[f"{name}.outcome"] = s.get("outcome")
        for k, v in (s.get("numbers") or {}).items():
            vals[f"{name}.{k}"] = v
    return vals


def fill(text: str, values: dict, cases=None) -> tuple[str, list[str]]:
    """``text`` with every marker of a case in ``cases`` (default: any case
    in ``values``) rewritten from ``values``; and the problems found (a key
    no run produces, a format that does not apply)."""
    problems = []
    known = {k.split(".", 1)[0] for k in values} if cases is None else set(cases)

    def sub(m):
        key, fmt = m.group("key"), m.group("fmt") or "{}"
        if key.split(".", 1)[0] not in known:
            return m.group(0)
        if key not in values:
            problems.append(f"{key}: no such number in the run's summary.json "
                            f"(has: {', '.join(sorted(values))})")
            return m.group(0)
        try:
            new = fmt.format(values[key])
        except (ValueError, TypeError, IndexError, KeyError) as e:
            problems.append(f"{key}: format {fmt!r} does not apply to {values[key]!r}: {e}")
            return m.group(0)
        return m.group(0)[:m.start("text") - m.start()] + new + "<!-- /number -->"

    return _MARK.sub(sub, text), problems


def image_difference(a, b) -> float:
    """Largest mean absolute grey-level difference (0..1) over the 8 x 8
    tiles of two pictures (files or arrays); ``inf`` when their sizes differ."""
    import numpy as np
    from PIL import Image

    def grey(x):
        im = Image.open(x) if isinstance(x, (str, Path)) else Image.fromarray(x)
        if im.mode in ("RGBA", "LA", "P"):
            im = im.convert("RGBA")
            white = Image.new("RGBA", im.size, (255, 255, 255, 255))
            im = Image.alpha_composite(white, im)
        return np.asarray(im.convert("L"), dtype=float) / 255.0

    ga, gb = grey(a), grey(b)
    if ga.shape != gb.shape:
        return float("inf")
    h, w = ga.shape
    d = np.abs(ga - gb)
    H, W = -(-h // TILE) * TILE, -(-w // TILE) * TILE
    d = np.pad(d, ((0, H - h), (0, W - w)))
    tiles = d.reshape(H // TILE, TILE, W // TILE, TILE).mean(axis=(1, 3))
    return float(tiles.max())


def regenerate(cases=None, check=False, out=None, log=print) -> list[str]:
    """Run the case studies (all of :data:`CASES` by default); rewrite the
    quoted numbers and the figures, or with ``check=True`` only compare them.
    Returns the problems (with ``check``: every difference)."""
    cases = list(CASES) if not cases else list(cases)
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        return [f"not a case study here: {', '.join(unknown)} (known: {', '.join(CASES)})"]
    problems: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(out) if out else Path(tmp)
        tmp.mkdir(parents=True, exist_ok=True)
        summaries = {}
        for name in cases:
            log(f"running {name} ...")
            summaries[name] = run_case(name, tmp)
            log(f"  {summaries[name].get('outcome')}")
        values = values_of(summaries)
        for page in pages():
            text = page.read_text()
            new, probs = fill(text, values, cases)
            problems += [f"{page.relative_to(ROOT)}: {p}" for p in probs]
            if new == text:
                continue
            if check:
                for a, b in zip(_MARK.finditer(text), _MARK.finditer(new)):
                    if a.group("text") != b.group("text"):
                        problems.append(f"{page.relative_to(ROOT)}: {a.group('key')} is "
                                        f"quoted as {a.group('text')!r}; the run gives "
                                        f"{b.group('text')!r}")
            else:
                page.write_text(new)
                log(f"wrote {page.relative_to(ROOT)}")
        for name in cases:
            made = tmp / name / f"{name}.png"
            dst = IMAGES / f"scenario_{name}.png"
            if not made.is_file():
                problems.append(f"avblocks run {name} wrote no {name}.png")
                continue
            if check:
                if not dst.is_file():
                    problems.append(f"{dst.relative_to(ROOT)} is missing")
                    continue
                diff = image_difference(dst, made)
                if diff > TILE_TOLERANCE:
                    problems.append(f"{dst.relative_to(ROOT)} differs from what "
                                    f"`avblocks run {name}` draws now (largest tile "
                                    f"difference {diff:.3f} > {TILE_TOLERANCE})")
            elif not dst.is_file() or image_difference(dst, made) > TILE_TOLERANCE:
                shutil.copyfile(made, dst)
                log(f"wrote {dst.relative_to(ROOT)}")
            else:                       # the same picture: keep the committed bytes
                log(f"kept {dst.relative_to(ROOT)} (the same within tolerance)")
    return problems


def main(argv=None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if args == ["--list"]:
        for page, key, fmt, text in quoted():
            print(f"{str(page.relative_to(ROOT)):28s} {key:36s} {fmt:14s} {text}")
        return 0
    check = "--check" in args
    names = [a for a in args if a != "--check"]
    problems = regenerate(names, check=check)
    for p in problems:
        print(p, file=sys.stderr)
    if check and not problems:
        print("the quoted numbers and the case-study figures match the runs")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
