"""What a careless instructor or an odd file name does to ``avblocks lab check``.

Found by attacking the grader (issue 46), each once a traceback, a hang, a
wrong grade or a broken machine, now refused (status 2, one line, before
anything is graded) or harmless:

* ``--extra-checks`` pointing at the class folder imported every
  submission into the grader as the instructor's trusted code;
* ``--gradescope`` to a folder, an empty path, an unwritable folder: a
  traceback after the whole run; to a device or a pipe (``/dev/null``,
  ``/dev/stdout``): replaced by a regular file (as root, the machine's
  ``/dev/null``);
* a FIFO in the class folder hung the grader before any student ran;
* a file name that is a spreadsheet formula (``=HYPERLINK(...)``), holds a
  newline, a terminal escape or a byte that is not UTF-8: a formula in
  the CSV, escapes in the terminal, a ``UnicodeEncodeError`` on a strict
  UTF-8 stdout (the class's CSV lost);
* ``python -m avblocks`` run inside a class folder imports its files as
  the grader's own modules: refused with the module's name.

The truth each asserts is outside the grader: the file system (what was
written, what a FIFO's reader got), Python's ``csv`` reader, a strict
UTF-8 encoder.
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import subprocess
import sys
import threading
import types
from pathlib import Path

import pytest

from avblocks.labs import cli, get

HERE = Path(__file__).resolve().parent
SRC = HERE.parents[1] / "src"
SOLUTION = HERE / "solutions" / "lab1_kinematics.py"


def _cli(*args, cwd=None, env=None, timeout=300):
    env = {**os.environ, **(env or {}),
           "PYTHONPATH": os.pathsep.join(x for x in (str(SRC), os.environ.get("PYTHONPATH")) if x)}
    return subprocess.run([sys.executable, "-P", "-m", "avblocks", "lab", *args],
                          capture_output=True, env=env, timeout=timeout, cwd=cwd)


def _refused(p, option, says):
    err = p.stderr.decode()
    assert p.returncode == 2 and "Traceback" not in err, err
    assert f"in parameter '{option}'" in err and says in err, err


def test_extra_checks_in_the_class_folder_are_refused(tmp_path):
    marker = tmp_path / "imported.txt"
    folder = tmp_path / "class"
    folder.mkdir()
    shutil.copyfile(SOLUTION, folder / "alice.py")
    (folder / "mallory.py").write_text(f"open({str(marker)!r}, 'w').write('ran')\nLAB = 1\n")
    for target, extra in ((folder, folder), (folder, "."), (folder / "alice.py", folder)):
        p = _cli("check", "1", str(target), "--csv", "--extra-checks", str(extra),
                 cwd=folder if extra == "." else None)
        _refused(p, "--extra-checks", "the extra checks' folder is the folder of the "
                                      "submissions")
    assert not marker.exists()              # no student's file ran in the grader


def test_gradescope_targets_that_cannot_be_a_results_file_are_refused_first(tmp_path):
    (tmp_path / "adir").mkdir()
    for target, says in ((tmp_path / "adir", "a folder, not a file"),
                         ("", "an empty path"),
                         (tmp_path / "no" / "r.json", "the folder of the results file does "
                                                      "not exist")):
        _refused(_cli("check", "1", str(SOLUTION), "--gradescope", str(target)),
                 "--gradescope", says)
    if os.geteuid() != 0:                   # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        _refused(_cli("check", "1", str(SOLUTION), "--gradescope", str(ro / "r.json")),
                 "--gradescope", "cannot be written")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs")
def test_gradescope_into_a_pipe_writes_into_it_and_never_replaces_it(tmp_path):
    """``--gradescope /dev/stdout`` or ``/dev/null``: what is there is not a
    regular file, so it is written in place (a FIFO here, read by a thread,
    stands for both; replacing /dev/null as root broke the machine)."""
    fifo = tmp_path / "results.fifo"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_text()), daemon=True)
    reader.start()
    p = _cli("check", "1", str(SOLUTION), "--gradescope", str(fifo))
    reader.join(30)
    assert p.returncode == 0, p.stderr.decode()
    assert fifo.is_fifo()                   # still the pipe, not a file put in its place
    assert json.loads(got[0])["score"] == 5.0


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs")
def test_a_fifo_in_the_class_folder_is_not_a_submission_and_no_hang(tmp_path):
    os.mkfifo(tmp_path / "a_fifo.py")
    shutil.copyfile(SOLUTION, tmp_path / "b.py")
    p = _cli("check", "1", str(tmp_path), "--csv", timeout=120)
    assert p.returncode == 1, p.stderr.decode()
    rows = list(csv.DictReader(io.StringIO(p.stdout.decode())))
    assert [(r["file"], r["passed"]) for r in rows] == [("a_fifo.py", "no"), ("b.py", "yes")]
    assert rows[0]["failed"] == "load: not a regular file (a folder, a pipe or a device?)"
    p = _cli("check", "1", str(tmp_path / "a_fifo.py"), timeout=60)        # alone, too
    assert p.returncode == 1 and b"not a regular file" in p.stdout


ODD = "=HYPERLINK(\"x\",\"y\")\n\x1b[31m"        # a formula, a newline, an escape


@pytest.mark.skipif(sys.platform != "linux", reason="any bytes in a file name: Linux")
def test_odd_file_names_reach_no_spreadsheet_formula_terminal_or_traceback(tmp_path):
    """One file whose name is a formula, holds a newline, a terminal escape
    and a byte that is not UTF-8, graded in a folder (``--csv``,
    ``--json``, the table) and alone, on a strict UTF-8 stdout."""
    name = os.fsencode(ODD) + b"\xff.py"
    shutil.copyfile(get(1).template, os.path.join(os.fsencode(tmp_path), name))
    strict = {"PYTHONIOENCODING": "utf-8:strict"}
    outs = {}
    for form in ("--csv", "--json", None):
        p = _cli("check", "1", str(tmp_path), *([form] if form else []), env=strict)
        assert p.returncode == 1 and b"Traceback" not in p.stderr, p.stderr.decode()
        outs[form] = p.stdout.decode("utf-8")         # strict: valid UTF-8
    rows = list(csv.reader(io.StringIO(outs["--csv"])))
    assert len(rows) == 2 and len(rows[1]) == 9
    cell = rows[1][0]
    # no cell a spreadsheet reads as a formula; the name printable on one line
    assert not any(c.startswith(("=", "+", "-", "@")) for r in rows[1:] for c in r)
    assert cell == "'" + "=HYPERLINK(\"x\",\"y\")??[31m\\xff.py" and cell.isprintable()
    assert json.loads(outs["--json"])[0]["file"].endswith("\\xff.py")
    assert "\x1b" not in outs[None] and "?[31m\\xff.py  FAIL  1/5" in outs[None]
    p = _cli("check", "1", os.path.join(os.fsencode(tmp_path), name).decode(
        "utf-8", "surrogateescape"), env=strict)
    text = p.stdout.decode("utf-8")
    assert p.returncode == 1 and b"Traceback" not in p.stderr, p.stderr.decode()
    assert "\x1b" not in text and text.splitlines()[0].endswith("?[31m\\xff.py")


def test_a_grader_that_imported_from_the_class_folder_refuses_to_grade_it(tmp_path):
    """``python -m avblocks`` inside a class folder: a submission named like
    a module the grader imports was imported as the grader's own code. What
    was imported cannot be undone (``avblocks`` or ``python -P -m``, say the
    docs); the grader refuses, naming the module, and takes the folder off
    its path."""
    shadow = types.ModuleType("random_homework")
    shadow.__file__ = str(tmp_path / "random_homework.py")
    sys.modules["random_homework"] = shadow
    sys.path.insert(0, str(tmp_path))
    try:
        with pytest.raises(cli.ParameterError, match="imported random_homework from the "
                                                     "folder it grades"):
            cli._keep_off_the_path(tmp_path)
    finally:
        del sys.modules["random_homework"]
    cli._keep_off_the_path(tmp_path)
    assert str(tmp_path) not in sys.path


def test_a_module_of_the_folder_imported_through_its_package_shadows_nothing(tmp_path):
    """CI imported the templates as ``src.avblocks.labs.templates.lab1_kinematics``
    (through the namespace package ``src``, the checkout on the path) and the
    grader then refused to grade the untouched template: a submodule is reached
    through its package, never through the folder on the path, so it shadows
    no name a student's file could take."""
    sub = types.ModuleType("pkg_of_tests.lab1_kinematics")
    sub.__file__ = str(tmp_path / "lab1_kinematics.py")
    sys.modules[sub.__name__] = sub
    try:
        assert cli._imported_from(tmp_path) == []
        cli._keep_off_the_path(tmp_path)            # no refusal
    finally:
        del sys.modules[sub.__name__]
