"""Hostile submissions (``tests/labs/hostile/``) against the grader.

One class folder holds every attack beside three honest files (a correct
solution that imports ``random`` and ``numpy``, a wrong one, the untouched
template) and is graded by the real command line, as an instructor would:
``avblocks lab check 1 DIR --json``. Asserted, as issue 46 asks:

* every attack fails with the message its docstring names (``expect:``),
  or changes nothing (``passes: yes``); status 1, no traceback anywhere;
* the honest files get exactly the verdicts and messages they get when
  each is graded alone (the independent truth: a run with no attacker);
* no process any attack started is left (each carries a per-run marker,
  looked up with psutil), and the grader leaves no child of its own;
* no file outside the student's own temporary folder was written (the
  other submission, a planted file, ``/tmp``, the grader's package).

Signals to the grader need Landlock's signal scoping (Linux 6.12+) to be
refused, and the fallbacks (no Landlock) are tested with the grader
running from a copy of the package, so that nothing here can change the
checkout.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import psutil
import pytest

from avblocks.labs import get, oscalls, run_checks

from .mutations import source

HERE = Path(__file__).resolve().parent
HOSTILE = HERE / "hostile"
ROOT = HERE.parents[1]
SRC = ROOT / "src"
SOLUTION = HERE / "solutions" / "lab1_kinematics.py"
#: a student's signals to the grader and its supervisor are refused: by
#: Landlock's scoping (ABI 6+, Linux 6.12+) or by the seccomp filter
SCOPED = oscalls.landlock_abi() >= 6 or oscalls.seccomp_arch() is not None


def _need_scoping():
    """Signals to outside processes are refused only under Landlock ABI 6+
    or seccomp (Linux x86-64, arm64): skip elsewhere on a user's machine,
    never in CI."""
    if not SCOPED and not os.environ.get("CI"):
        pytest.skip("needs Landlock ABI 6 (Linux 6.12+) or seccomp to refuse a student's "
                    "signals")


def expectations(text):
    """``(passes, [texts its messages must hold])`` from a hostile file's docstring."""
    passes = bool(re.search(r"^passes: yes$", text, re.M))
    return passes, re.findall(r"^expect: (.+)$", text, re.M)


#: attacks that only a platform feature stops, with the test of that feature:
#: skipped where it is missing on a user's machine, never in CI
NEEDS = {"signals.py": lambda: SCOPED, "kills_supervisor.py": lambda: SCOPED,
         "reads_files.py": lambda: oscalls.landlock_abi() >= 1,
         "sockets_and_modes.py": lambda: oscalls.seccomp_arch() is not None}


def attacks():
    names = sorted(p.name for p in HOSTILE.glob("*.py"))
    return [n for n in names if n not in NEEDS or NEEDS[n]() or os.environ.get("CI")]


def _cli(*args, env=None, src=SRC, timeout=900, cwd=None):
    """``avblocks lab ARGS`` as a shell runs it (``-P``: like the console
    script, the current folder is not on the grader's own path, so the
    grader can run inside the class folder)."""
    env = {**os.environ, **(env or {}),
           "PYTHONPATH": os.pathsep.join(x for x in (str(src), os.environ.get("PYTHONPATH")) if x)}
    return subprocess.run([sys.executable, "-P", "-m", "avblocks", "lab", *args],
                          capture_output=True, text=True, env=env, timeout=timeout, cwd=cwd)


def _marked(token):
    out = []
    for p in psutil.process_iter(["pid", "cmdline", "status"]):
        try:
            if p.info["status"] != psutil.STATUS_ZOMBIE and any(
                    token in a for a in (p.info["cmdline"] or [])):
                out.append((p.pid, p.info["cmdline"]))
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            pass
    return out


def _children():
    return [c for c in psutil.Process().children(recursive=True)
            if c.status() != psutil.STATUS_ZOMBIE]


def _class_folder(folder, token, names):
    for n in names:
        (folder / n).write_text((HOSTILE / n).read_text().replace("TOKEN", token))
    (folder / "alice.py").write_text("import random\nimport numpy\n" + SOLUTION.read_text())
    (folder / "carol.py").write_text(source(1, "wrong_sign"))
    shutil.copyfile(get(1).template, folder / "dave.py")


def _grade_the_class(folder, token, names):
    """Grade the class folder from inside it; what the run left behind
    (also in the grader's temporary folder, TMPDIR)."""
    tmp = folder.parent / "grader-tmp"
    tmp.mkdir()
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    children = {c.pid for c in _children()}
    try:
        # graded from inside the folder, beside its random.py, numpy.py, avblocks.py;
        # the grader's environment holds a "secret" (reads_environ.py looks for it)
        p = _cli("check", "1", ".", "--json", "--timeout", "10", cwd=folder,
                 env={"AVBLOCKS_HOSTILE_SECRET": token, "TMPDIR": str(tmp)})
        survivors = _marked(token)
        left = [c for c in _children() if c.pid not in children]
    finally:
        for pid, _ in _marked(token):          # never leave them to the next test
            try:
                psutil.Process(pid).kill()
            except psutil.NoSuchProcess:
                pass
        sentinel = SRC / "avblocks" / "labs" / f"_hostile_sentinel_{token}.txt"
        planted = [q for q in (sentinel, Path("/tmp") / f"avblocks-hostile-{token}.txt",
                               Path("/tmp") / f"avblocks-hostile-{token}-pickle") if q.exists()]
        for q in planted:
            q.unlink()
    doc = json.loads(p.stdout) if p.stdout.strip().startswith("[") else None
    planted += sorted(tmp.iterdir())            # every student's folder removed
    for q in planted:
        if q.is_dir():
            oscalls.remove_tree(q)
    return p, doc, before, survivors, left, planted


def test_a_class_folder_full_of_attacks(tmp_path):
    """Every attack of tests/labs/hostile/ in one class folder with three
    honest files, graded by the command line from inside the folder. One
    test (not one per attack) so that the class is graded once, also
    under pytest-xdist; every failure is collected before the assert."""
    folder = tmp_path / "class"
    folder.mkdir()
    token = uuid.uuid4().hex
    names = attacks()
    _class_folder(folder, token, names)
    p, doc, before, survivors, left, planted = _grade_the_class(folder, token, names)
    problems = []
    # the run: status 1, no traceback anywhere, one report per file
    if p.returncode != 1 or "Traceback" in p.stdout + p.stderr or p.stderr or doc is None:
        pytest.fail(f"status {p.returncode}\n{p.stdout[-3000:]}\n{p.stderr[-3000:]}")
    got = {Path(r["file"]).name: r for r in doc}
    if sorted(got) != sorted(names + ["alice.py", "carol.py", "dave.py"]):
        problems.append(f"graded {sorted(got)}")
    # every attack fails with the message its docstring names, or changes nothing
    for name in names:
        report = got.get(name)
        passes, needles = expectations((HOSTILE / name).read_text())
        if report is None or not (needles or passes):
            problems.append(f"{name}: no report, or its docstring expects nothing")
            continue
        if passes != report["passed"]:
            problems.append(f"{name}: passed={report['passed']}: {report['checks']}")
        text = "\n".join(c["message"] for c in report["checks"] if not c["passed"])
        problems += [f"{name}: {n!r} not in {text!r}" for n in needles if n not in text]
        problems += [f"{name}: a message that is not one printable line: {c['message']!r}"
                     for c in report["checks"] if not c["message"].isprintable()]
    # the honest files: exactly the verdicts and messages they get graded alone
    for name, passed in (("alice.py", True), ("carol.py", False), ("dave.py", False)):
        alone = run_checks(get(1), folder / name, timeout=10)
        together = [(c["name"], c["passed"], c["message"]) for c in got[name]["checks"]]
        if alone.passed is not passed or together != [(c.name, c.passed, c.message)
                                                      for c in alone.checks]:
            problems.append(f"{name}: alone {alone.checks}, in the class {together}")
    # no process left, no file written outside the students' own folders
    if survivors or left:
        problems.append(f"left running: {survivors} {left}")
    now = {q.name: q.read_bytes() for q in folder.iterdir()}
    if now != before:
        problems.append(f"the folder changed: {sorted(set(now) ^ set(before))} "
                        f"{[n for n in now if n in before and now[n] != before[n]]}")
    if planted:
        problems.append(f"files planted: {planted}")
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("off", ["", "landlock"])
def test_signals_to_the_grader_are_refused(tmp_path, off):
    """Also without Landlock (as before Linux 6.12, when only the seccomp
    filter refuses them): the grader and its supervisor cannot be stopped or
    killed, so a daemon started after the attempt is still collected."""
    _need_scoping()
    if off and oscalls.seccomp_arch() is None and not os.environ.get("CI"):
        pytest.skip("needs seccomp (Linux x86-64, arm64)")
    token = uuid.uuid4().hex
    folder = tmp_path / "class"
    folder.mkdir()
    _class_folder(folder, token, ["signals.py", "kills_supervisor.py"])
    src = _package_copy(tmp_path) if off else SRC       # nothing may touch the checkout
    try:
        p = _cli("check", "1", str(folder), "--json", "--timeout", "10", src=src,
                 env={"AVBLOCKS_LAB_DISABLE": off})
        survivors = _marked(token)
    finally:
        for pid, _ in _marked(token):
            psutil.Process(pid).kill()
    assert p.returncode == 1 and "Traceback" not in p.stdout + p.stderr
    doc = {Path(r["file"]).name: r for r in json.loads(p.stdout)}
    text = "\n".join(c["message"] for c in doc["signals.py"]["checks"])
    for needle in expectations((HOSTILE / "signals.py").read_text())[1]:
        assert needle in text
    assert doc["alice.py"]["passed"] and not doc["carol.py"]["passed"]
    assert doc["kills_supervisor.py"]["passed"] and survivors == []


# ---------------------------------------------------------------- without Landlock
def _package_copy(tmp_path):
    """The avblocks package copied, so that a fallback test cannot change
    the checkout whatever a hostile file does."""
    dst = tmp_path / "src"
    shutil.copytree(SRC / "avblocks", dst / "avblocks",
                    ignore=shutil.ignore_patterns("__pycache__", "node_modules"))
    return dst


def test_without_landlock_a_write_into_the_folder_fails_the_writer(tmp_path):
    src = _package_copy(tmp_path)
    folder = tmp_path / "class"
    folder.mkdir()
    token = uuid.uuid4().hex
    (folder / "writes_folder.py").write_text(
        (HOSTILE / "writes_folder.py").read_text().replace("TOKEN", token))
    shutil.copyfile(SOLUTION, folder / "alice.py")
    try:
        p = _cli("check", "1", str(folder), "--json", "--timeout", "10", src=src,
                 env={"AVBLOCKS_LAB_DISABLE": "landlock"})
    finally:
        Path(f"/tmp/avblocks-hostile-{token}.txt").unlink(missing_ok=True)
    assert p.returncode == 1 and "Traceback" not in p.stdout + p.stderr
    doc = {Path(r["file"]).name: r for r in json.loads(p.stdout)}
    # alice was graded from the copy read before any student's code ran
    assert doc["alice.py"]["passed"] and doc["alice.py"]["checks_passed"] == 5
    assert doc["alice.py"]["limits"]["files"] == "not restricted: Landlock switched off"
    files = {c["name"]: c["message"] for c in doc["writes_folder.py"]["checks"]}["files"]
    assert files.startswith("the folder changed while this submission ran (alice.py, "
                            "zzz_planted.py): a submission must not write files")
    assert (folder / "alice.py").read_text().startswith("raise SystemExit")   # it did write


def test_without_landlock_a_write_into_the_grader_stops_the_run(tmp_path):
    src = _package_copy(tmp_path)
    folder = tmp_path / "class"
    folder.mkdir()
    token = uuid.uuid4().hex
    (folder / "writes_grader.py").write_text(
        (HOSTILE / "writes_grader.py").read_text().replace("TOKEN", token))
    shutil.copyfile(SOLUTION, folder / "zoe.py")
    p = _cli("check", "1", str(folder), "--csv", "--timeout", "10", src=src,
             env={"AVBLOCKS_LAB_DISABLE": "landlock"})
    assert p.returncode == 2 and "Traceback" not in p.stdout + p.stderr
    assert "the grader's own files (the avblocks package) changed while writes_grader.py " \
           "ran; reinstall avblocks and grade in a read-only installation" in p.stderr
    assert (src / "avblocks" / "labs" / f"_hostile_sentinel_{token}.txt").exists()


def test_without_seccomp_a_changed_mode_fails_the_writer_not_the_class(tmp_path):
    """Landlock does not stop chmod: a submission that changed the mode of a
    grader's file used to stop the whole class's run (status 2, no CSV).
    Now only the content of the grader's files stops it; a changed mode
    fails the submission that changed it, is put back, and the class goes on."""
    src = _package_copy(tmp_path)
    module = src / "avblocks" / "labs" / "registry.py"
    mode = module.stat().st_mode & 0o777
    folder = tmp_path / "class"
    folder.mkdir()
    token = uuid.uuid4().hex
    (folder / "modes.py").write_text(
        (HOSTILE / "sockets_and_modes.py").read_text().replace("TOKEN", token))
    shutil.copyfile(SOLUTION, folder / "zoe.py")
    p = _cli("check", "1", str(folder), "--json", "--timeout", "10", src=src,
             env={"AVBLOCKS_LAB_DISABLE": "seccomp"})
    assert p.returncode == 1 and "Traceback" not in p.stdout + p.stderr, p.stderr
    doc = {Path(r["file"]).name: r for r in json.loads(p.stdout)}
    assert doc["zoe.py"]["passed"] and doc["zoe.py"]["points"] == 5
    files = {c["name"]: c["message"] for c in doc["modes.py"]["checks"]}["files"]
    assert files == ("it changed the mode of the grader's own files (labs/registry.py): a "
                     "submission must not touch them; their modes were put back")
    assert doc["modes.py"]["points"] == 0 and module.stat().st_mode & 0o777 == mode


SLEEPER = ("\n\ndef wheels_to_cmd(*a, **k):\n    import subprocess, sys, time\n"
           "    subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(3600)', "
           "TOKEN])\n    time.sleep(3600)\n")


def _grader_on_a_sleeper(tmp_path, token):
    f = tmp_path / "sleepy.py"
    f.write_text(SOLUTION.read_text() + SLEEPER.replace("TOKEN", repr(token)))
    tmp = tmp_path / "tmp"                   # the grader's temporary folders go here
    tmp.mkdir()
    env = {**os.environ, "TMPDIR": str(tmp),
           "PYTHONPATH": os.pathsep.join(x for x in (str(SRC), os.environ.get("PYTHONPATH")) if x)}
    p = subprocess.Popen([sys.executable, "-P", "-m", "avblocks", "lab", "check", "1", str(f)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    end = time.monotonic() + 120
    while not _marked(token) and time.monotonic() < end and p.poll() is None:
        time.sleep(0.1)
    return p


def test_killing_the_grader_kills_what_the_student_started(tmp_path):
    """SIGKILL to the grader (no handler, no finally): the supervisor sees
    its control socket close and kills the student's process tree."""
    token = uuid.uuid4().hex
    p = _grader_on_a_sleeper(tmp_path, token)
    try:
        assert _marked(token), "the student's sleeper never started"
        p.kill()
        p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    end = time.monotonic() + 10
    while _marked(token) and time.monotonic() < end:
        time.sleep(0.1)
    assert _marked(token) == []
    # and the student's temporary folder is gone (the supervisor removed it)
    end = time.monotonic() + 10
    while list((tmp_path / "tmp").iterdir()) and time.monotonic() < end:
        time.sleep(0.1)
    assert list((tmp_path / "tmp").iterdir()) == []


def test_ctrl_c_stops_the_grader_and_everything_the_student_started(tmp_path):
    """SIGINT to the grader while a check runs (the student's code sleeps
    after starting a sleeper): status 130, one line, nothing left."""
    token = uuid.uuid4().hex
    p = _grader_on_a_sleeper(tmp_path, token)
    try:
        assert _marked(token), "the student's sleeper never started"
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    time.sleep(0.5)
    assert p.returncode == 130 and "Traceback" not in out + err
    assert err.strip().endswith("avblocks: interrupted")
    assert _marked(token) == []
