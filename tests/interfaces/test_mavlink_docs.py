"""docs/drones.md's MAVLink commands run as written, against the emulator.

Every shell block of the page's MAVLink parts carries a marker on the line
before it: ``<!-- test: mavlink NAME -->`` blocks are run here, in one
test (they use the default ports, so not in parallel), with two changes
only: ``avblocks`` is this interpreter's ``python -m avblocks``, and the
flight gets ``--set t_final=2`` (the page's runs are the full case study,
flown by test_mavlink_formation.py) and the emulator a ``--log``;
``<!-- external: why -->`` blocks are PX4's or ArduPilot's own commands,
which this machine cannot run (the page says which ran against what).
A flown block must end complete, every vehicle landed, each vehicle
matched by pre-flight to its own agent's start position (the scenario's
``start_positions``) within 5 cm: the page sets its vehicles down where
the scenario starts them."""

import json
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from avblocks.scenarios.drone_formation import start_positions

from ._mavlink import need_pymavlink, read_log
from .conftest import env

DOC = Path(__file__).resolve().parents[2] / "docs" / "drones.md"
MARK = re.compile(r"<!-- (test: mavlink [\w ]+|external: [^>]*) -->")


def _sections(text):
    """The page's MAVLink parts: the command-line example, what the
    vehicles must do on their own, and the MAVLink section."""
    a = text.index("From the command line")
    b = text.index("## Flight phases")
    c = text.index("## What the vehicle must do on its own")
    d = text.index("## Crazyflies")
    return text[a:b] + text[c:d]


def shell_blocks(text):
    """[(marker or None, code)] for every ```bash / ```sh block of ``text``."""
    out = []
    lines = text.splitlines()
    k = 0
    while k < len(lines):
        if lines[k].strip() in ("```bash", "```sh", "```console", "```shell"):
            j = k + 1
            while lines[j].strip() != "```":
                j += 1
            prev = lines[k - 1].strip() if k else ""
            m = MARK.fullmatch(prev)
            out.append((m.group(1) if m else None, "\n".join(lines[k + 1:j])))
            k = j
        k += 1
    return out


def commands(code):
    """The commands of a block (continuation lines joined), as argv lists,
    each with whether it runs in the background (``&``)."""
    out = []
    for line in code.replace("\\\n", " ").splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        bg = line.rstrip().endswith("&")
        out.append((shlex.split(line.rstrip().rstrip("&")), bg))
    return out


def test_every_mavlink_shell_block_is_run_here_or_says_why_not():
    blocks = shell_blocks(_sections(DOC.read_text()))
    assert len(blocks) >= 5
    unmarked = [code for mark, code in blocks if mark is None]
    assert not unmarked, f"shell blocks without a test/external marker: {unmarked}"
    for mark, code in blocks:
        if mark.startswith("test:"):
            assert all(argv[0] == "avblocks" for argv, _ in commands(code)), code


def _run_block(name, code, tmp):
    procs = []
    logs = []
    try:
        result = None
        for argv, bg in commands(code):
            argv = [sys.executable, "-m", "avblocks", *argv[1:]]
            if bg:
                log = tmp / f"emulator-{len(logs)}.jsonl"
                logs.append(log)
                p = subprocess.Popen([*argv, "--log", str(log), "--duration", "150"],
                                     env=env(), cwd=tmp, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
                procs.append(p)
                t_end = time.monotonic() + 30
                while not (log.exists() and log.stat().st_size):
                    assert p.poll() is None and time.monotonic() < t_end, p.stdout.read()
                    time.sleep(0.05)
            else:
                result = subprocess.run([*argv, "--set", "t_final=2"], env=env(), cwd=tmp,
                                        capture_output=True, text=True, timeout=240)
        return result, logs
    finally:
        for p in procs:
            p.terminate()
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:  # pragma: no cover
                p.kill()


@pytest.mark.slow
def test_the_pages_mavlink_commands_run_as_written(tmp_path):
    need_pymavlink()
    blocks = [(m, c) for m, c in shell_blocks(_sections(DOC.read_text()))
              if m.startswith("test:")]
    names = [m.split(None, 2)[2] for m, _ in blocks]
    assert {"quick start", "refused", "px4 origins", "ardupilot"} <= set(names), names
    for (_, code), name in zip(blocks, names):
        tmp = tmp_path / name.replace(" ", "-")
        tmp.mkdir()
        res, logs = _run_block(name, code, tmp)
        text = res.stdout + res.stderr
        em = read_log(logs[0])
        n = em[0]["n"]
        if name == "refused":
            # the vehicles at their firmware's defaults: refused, nothing armed
            assert res.returncode == 2, text
            flat = " ".join(text.split())
            assert ("pre-flight check failed, nothing was commanded: uav1: COM_OBL_RC_ACT "
                    "= 0 (Position mode): when the set-points stop it keeps flying") in flat
            assert not [e for e in em if e["ev"] == "armed"]
            continue
        assert res.returncode == 0, text
        summary = json.loads((tmp / "out" / "summary.json").read_text())
        assert summary["status"] == "complete"
        # the page's vehicles stand on the scenario's start positions (its own
        # start_positions): pre-flight gave uav k agent k, each within 5 cm
        fl = [json.loads(s) for s in (tmp / "out" / "flight-log.jsonl").read_text()
              .splitlines()]
        (slots,) = [r for r in fl if r["ev"] == "slots"]
        assert [m["vehicle"] for m in slots["mapping"]] == [f"uav{k + 1}" for k in range(n)]
        np.testing.assert_allclose([m["slot"] for m in slots["mapping"]],
                                   start_positions(n)[:, :2], atol=1e-3)
        assert max(m["distance"] for m in slots["mapping"]) < 0.05, slots
        t_end = time.monotonic() + 15
        while time.monotonic() < t_end:           # the emulator's log, up to now
            em = read_log(logs[0])
            if len({e["sysid"] for e in em if e["ev"] == "landed"}) == n:
                break
            time.sleep(0.2)
        assert len({e["sysid"] for e in em if e["ev"] == "landed"}) == n, name
        start = [e for e in em if e["ev"] == "start"][0]
        if name == "ardupilot":
            assert start["flavor"] == "ardupilot" and start["link"] == "tcp"
            assert start["ports"] == [5760, 5770]
        else:
            assert start["flavor"] == "px4" and start["ports"][0] == 14540
            assert start["vehicle_ports"][0] == 14580
