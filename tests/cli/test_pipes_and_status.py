"""The command line as scripts use it, through real pipes: a command whose
reader goes away ends quietly (no traceback, the documented status),
``--json`` prints one JSON document, and the exit statuses documented in
``avblocks --help`` and docs/cli.md are the same list."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _cmd():
    exe = shutil.which("avblocks", path=str(Path(sys.executable).parent))
    return [exe] if exe else [sys.executable, "-m", "avblocks"]


def _env():
    src = str(ROOT / "src")
    path = os.pathsep.join(x for x in (src, os.environ.get("PYTHONPATH")) if x)
    return {**os.environ, "PYTHONPATH": path}


def run_reader_gone(args, timeout=120):
    """Run ``avblocks ARGS`` with stdout a real pipe whose read end is
    closed before the command writes: every write meets EPIPE."""
    r, w = os.pipe()
    os.close(r)                       # the reader has gone before anything is written
    try:
        p = subprocess.run(_cmd() + args, stdout=w, stderr=subprocess.PIPE, text=True,
                           env=_env(), timeout=timeout)
    finally:
        os.close(w)
    return p


@pytest.mark.parametrize("args", [["list"], ["list", "--blocks"], ["list", "--json"],
                                  ["list", "--blocks", "--json"], ["--help"],
                                  ["list", "--help"], ["--version"], ["lab", "list"],
                                  ["lab", "list", "--json"]])
def test_a_command_ends_quietly_when_its_reader_has_gone(args):
    p = run_reader_gone(args)
    assert "Traceback" not in p.stderr and "BrokenPipe" not in p.stderr, p.stderr
    assert p.stderr == ""
    assert p.returncode == 0


def test_the_issues_pipeline_head_1():
    """``avblocks list --blocks | head -1``, as a shell runs it: the first
    line, status 0 on both sides of the pipe, nothing on stderr."""
    bash = shutil.which("bash")
    if bash is None:
        pytest.skip("needs bash")
    cmd = " ".join(_cmd())
    script = (f"{cmd} list --blocks | head -1; echo \"status ${{PIPESTATUS[0]}} "
              f"${{PIPESTATUS[1]}}\"")
    p = subprocess.run([bash, "-c", script], capture_output=True, text=True, env=_env(),
                       timeout=120)
    first, status = p.stdout.splitlines()
    assert first.startswith("blocks.") and status == "status 0 0"
    assert p.stderr == ""


def test_reader_gone_in_the_middle_of_a_long_output():
    """A reader that takes some lines then closes: the writer has more to
    write than the pipe holds (the JSON list of blocks, repeated by a
    scenario list), so the close meets a write in progress."""
    proc = subprocess.Popen(_cmd() + ["list", "--blocks", "--json"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=_env())
    head = proc.stdout.read(10)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    proc.wait(timeout=120)
    assert head.startswith(b"[")
    assert "Traceback" not in err and proc.returncode == 0, err


def test_list_json_is_what_list_prints():
    p = subprocess.run(_cmd() + ["list", "--json"], capture_output=True, text=True,
                       env=_env(), timeout=120)
    rows = json.loads(p.stdout)
    text = subprocess.run(_cmd() + ["list"], capture_output=True, text=True, env=_env(),
                          timeout=120).stdout
    names = [ln for ln in text.splitlines() if ln and not ln.startswith(" ")]
    assert [r["name"] for r in rows] == names and "nest" in names
    nest = next(r for r in rows if r["name"] == "nest")
    assert nest["kind"] == "yaml" and isinstance(nest["parameters"], dict)
    blocks = json.loads(subprocess.run(_cmd() + ["list", "--blocks", "--json"],
                                       capture_output=True, text=True, env=_env(),
                                       timeout=120).stdout)
    assert {"type": "vehicles.Unicycle"}.items() <= next(
        b for b in blocks if b["type"] == "vehicles.Unicycle").items()


def _statuses(text):
    """The statuses a list starts its entries with (a table row's first
    cell, or a line indented by two spaces)."""
    return {int(m) for m in re.findall(r"^(?:\| `|  )(\d+)", text, flags=re.M)}


def test_exit_statuses_are_documented_in_help_and_docs():
    from avblocks.cli import EXIT_STATUSES
    p = subprocess.run(_cmd() + ["--help"], capture_output=True, text=True, env=_env(),
                       timeout=120)
    assert EXIT_STATUSES.strip().splitlines()[1].split()[0] == "0"
    assert all(ln in p.stdout for ln in EXIT_STATUSES.strip().splitlines())
    page = (ROOT / "docs" / "cli.md").read_text()
    table = page[page.index("<!-- exit-statuses -->"):page.index("<!-- /exit-statuses -->")]
    assert _statuses(table) == {0, 1, 2, 3, 128} == _statuses(EXIT_STATUSES.replace(
        "128+N", "128"))


@pytest.mark.parametrize("args,status", [
    (["run", "no_such_scenario", "--quiet"], 2),
    (["run", "waypoints", "--set", "agents=-3", "--quiet"], 2),
    (["list", "--no-such-option"], 2),
])
def test_bad_input_is_status_2_with_one_message(args, status, tmp_path):
    p = subprocess.run(_cmd() + args, capture_output=True, text=True, env=_env(),
                       cwd=tmp_path, timeout=300)
    assert p.returncode == status
    assert "Traceback" not in p.stderr and "avblocks" in p.stderr
