"""Every ``avblocks`` command shown in docs/drones.md's worked example,
flight-layer and Crazyflie sections parses with the real command-line
parser, exactly as written (optional ``[...]`` parts included, the first of
``a|b`` alternatives taken): a renamed option or a value argparse cannot
take (``--geofence -4,4,-3,5,0,3`` read as an option) fails here. The
commands that fly are run by the flight tests (the emulator, the guard
and ``avblocks run drone_formation --robots crazyflies``); the ``ros2``
commands need ROS 2 and are not run."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

PAGE = Path(__file__).resolve().parents[2] / "docs" / "drones.md"
#: The sections of the page these tests cover (the MAVLink sections have theirs).
SECTIONS = ("## Worked example", "## Flight phases", "## Limits", "## Fail-safe",
            "## Crazyflies")


def _sections(text):
    parts = re.split(r"(?m)^(?=## )", text)
    return [p for p in parts if p.startswith(SECTIONS)]


def _commands(section):
    """``avblocks ...`` command lines of the fenced blocks of a section."""
    out = []
    for block in re.findall(r"(?ms)^\s*```[a-z]*\n(.*?)^\s*```", section):
        lines, cur = [], ""
        for ln in block.splitlines():
            cur += ln.strip()
            if cur.endswith("\\"):
                cur = cur[:-1] + " "
                continue
            lines.append(cur)
            cur = ""
        for ln in lines:
            ln = re.sub(r"\s+#\s.*$", "", ln).rstrip(" &")
            if ln.startswith("avblocks "):
                out.append(ln)
    return out


def _argv(cmd):
    """The arguments of a documented command: an optional part's brackets
    (``[--opt VALUE]``) dropped, the first of ``a|b`` alternatives taken."""
    out = []
    for a in shlex.split(cmd)[1:]:
        if a.startswith("[-"):
            a = a[1:]
        if a.endswith("]") and a.count("]") > a.count("["):
            a = a[:-1]
        if re.fullmatch(r"[\w.]+(\|[\w.]+)+", a):
            a = a.split("|")[0]
        out.append(a)
    return out


COMMANDS = [c for s in _sections(PAGE.read_text()) for c in _commands(s)]


def test_the_sections_show_commands():
    assert len(COMMANDS) >= 8
    assert any("--geofence -4,4,-3,5,0,3" in c for c in COMMANDS)
    assert any(c.startswith("avblocks crazyflies guard") for c in COMMANDS)


@pytest.mark.parametrize("cmd", COMMANDS)
def test_a_documented_command_parses(cmd):
    from avblocks.cli import build_parser
    argv = _argv(cmd)
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:
        raise AssertionError(f"docs/drones.md: {cmd!r} does not parse ({argv})") from e
    if "--geofence" in argv:
        from avblocks.interfaces.flight.cli import flight_options
        fence = argv[argv.index("--geofence") + 1]
        assert flight_options(args)["geofence"] == [float(v) for v in fence.split(",")]


def test_the_help_names_the_extra_the_docs_name():
    """``avblocks run --help`` and the page agree: the Crazyflie options come
    with the ``[crazyflie]`` extra (it said ``[ros2]``)."""
    from avblocks.cli import build_parser
    ap = build_parser()
    run = next(a for a in ap._subparsers._group_actions[0].choices.items()
               if a[0] == "run")[1]
    text = run.format_help()
    assert "Crazyflies (--robots crazyflies; extra [crazyflie])" in text
    assert "`[crazyflie]`" in PAGE.read_text()
