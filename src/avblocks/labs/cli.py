"""``avblocks lab``: list the labs, start one, check a submission or a folder.

    avblocks lab list [--json]
    avblocks lab start N [--force] [--to DIR]   # copies the template
    avblocks lab check N FILE [--json] [--gradescope results.json]
    avblocks lab check N DIR [--csv | --json]
        [--timeout SECONDS] [--memory MIB] [--seed N | --student ID]
        [--extra-checks DIR]

The student's code runs in a separate process that only computes (see
:mod:`avblocks.labs.grading`): loading the file and each check may take
``--timeout`` seconds (default 60; a finite number > 0), after which the
process is killed with everything it started and the check reported as
timed out; its address space is limited to ``--memory`` MiB (default
4096; 0: none) where the platform allows; what it prints is discarded.

``--seed N`` draws each check's cases from ``N`` instead of the lab page's
fixed cases (in a folder, each file's seed is drawn from ``N`` and its
name, and reported); ``--student ID`` draws them from the student's id.
``--extra-checks DIR`` adds an instructor's checks (:mod:`avblocks.labs.extra`).
``--gradescope PATH`` writes Gradescope's ``results.json`` for one file.

Exit status: 0 every check passed; 1 a check failed, timed out or the
student's code ended the process (for a folder: in at least one
submission); 2 bad input (an unknown or invalid option, no such lab, file
or folder, a file that ``start`` would overwrite, the grader's own files
changed while it ran).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import shutil
import stat
import sys
import tempfile
import time
from pathlib import Path

from ..core.errors import ParameterError
from .grading import (
    DEFAULT_MEMORY_MB,
    DEFAULT_TIMEOUT,
    MAX_TIMEOUT,
    GraderTampered,
    grade_all,
    run_checks,
)
from .registry import get, labs
from .remote import seed_for
from .report import CSV_COLUMNS, CSV_HELP, csv_row, gradescope, shown


def _seconds(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of seconds: {text!r}") from None
    if not (math.isfinite(v) and 0 < v <= MAX_TIMEOUT):
        raise argparse.ArgumentTypeError(
            f"must be a finite number of seconds > 0 and at most {MAX_TIMEOUT:g} (a day), "
            f"got {text!r}")
    return v


def _mib(text):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number of MiB: {text!r}") from None
    if v < 0 or v > 2 ** 40:
        raise argparse.ArgumentTypeError(f"must be a whole number of MiB >= 0 (0: no limit), "
                                         f"got {text!r}")
    return v


def _seed(text):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if not 0 <= v < 2 ** 63:
        raise argparse.ArgumentTypeError(f"must be a whole number in [0, 2**63), got {text!r}")
    return v


def _student(text):
    t = text.strip()
    if not t or len(t) > 200 or not t.isprintable():
        raise argparse.ArgumentTypeError("a student id is 1 to 200 printable characters")
    return t


def add_parser(sub):
    """The ``lab`` command group on an argparse sub-parser set."""
    p = sub.add_parser("lab", help="the lab course: list, start and check exercises")
    lsub = p.add_subparsers(dest="lab_command", required=True)
    li = lsub.add_parser("list", help="the labs and their templates")
    li.add_argument("--json", action="store_true", help="print one JSON document")
    li.set_defaults(fn=cmd_list)
    st = lsub.add_parser("start", help="copy lab N's template into the current folder")
    st.add_argument("number", help="the lab's number")
    st.add_argument("--force", action="store_true", help="overwrite an existing file")
    st.add_argument("--to", default=".", help="folder to copy into (default: here)")
    st.set_defaults(fn=cmd_start)
    ch = lsub.add_parser("check", help="check a submission (a file) or every .py in a folder; "
                                       "exit 0 only when every check passes")
    ch.add_argument("number", help="the lab's number")
    ch.add_argument("path", help="the student's file, or a folder of submissions")
    fmt = ch.add_mutually_exclusive_group()
    fmt.add_argument("--json", action="store_true", help="print one JSON document")
    fmt.add_argument("--csv", action="store_true",
                     help="one CSV row per submission, columns: " + ", ".join(CSV_COLUMNS))
    ch.add_argument("--timeout", type=_seconds, default=DEFAULT_TIMEOUT, metavar="SECONDS",
                    help=f"time limit of loading the file and of each check (default "
                         f"{DEFAULT_TIMEOUT:g}; a finite number > 0, at most "
                         f"{MAX_TIMEOUT:g}); a check past it fails as timed out")
    ch.add_argument("--memory", type=_mib, default=DEFAULT_MEMORY_MB, metavar="MIB",
                    help=f"address-space limit of the process running the student's code "
                         f"(default {DEFAULT_MEMORY_MB}; 0: none)")
    who = ch.add_mutually_exclusive_group()
    who.add_argument("--seed", type=_seed, default=None, metavar="N",
                     help="draw the cases from seed N instead of the lab page's fixed ones "
                          "(a folder: each file's seed from N and its name, in the report)")
    who.add_argument("--student", type=_student, default=None, metavar="ID",
                     help="draw the cases from this student's id (one file)")
    ch.add_argument("--extra-checks", default=None, metavar="DIR",
                    help="a folder of the instructor's check modules, run after the lab's "
                         "own (see docs/labs/index.md)")
    ch.add_argument("--gradescope", default=None, metavar="PATH",
                    help="also write Gradescope's results.json for the file to PATH")
    ch.set_defaults(fn=cmd_check)
    return p


def cmd_list(args):
    rows = [{"number": lab.number, "name": lab.name, "title": lab.title,
             "template": lab.template.name, "defines": list(lab.names)} for lab in labs()]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    for r in rows:
        print(f"{r['number']:>2}  {r['title']}\n    template {r['template']} "
              f"(write: {', '.join(r['defines'])})")
    return 0


def cmd_start(args):
    lab = get(args.number)
    folder = Path(args.to)
    if not folder.is_dir():
        raise ParameterError("no such folder", param="--to", expected="an existing folder",
                             found=str(folder))
    dst = folder / lab.template.name
    if dst.exists() and not args.force:
        raise ParameterError(f"{dst} exists; not overwriting it", param="--force",
                             expected="a new file, or --force to overwrite", found=str(dst))
    shutil.copyfile(lab.template, dst)
    print(f"wrote {dst}: write {', '.join(lab.names)} in it, then run\n"
          f"  avblocks lab check {lab.number} {dst}")
    return 0


_shown = shown                      # a file name as one line of printable text


def _results_target(text):
    """The ``--gradescope`` path, checked before anything is graded (a
    results file that cannot be written used to end a finished run in a
    traceback): not empty, not a folder, in a folder that exists and can
    be written."""
    if not text.strip():
        raise ParameterError("an empty path", param="--gradescope",
                             expected="the path of the results file", found=repr(text))
    target = Path(text)
    if target.is_dir():
        raise ParameterError("a folder, not a file", param="--gradescope",
                             expected="the path of the results file (results.json)",
                             found=text)
    folder = target.resolve().parent
    if not folder.is_dir():
        raise ParameterError("the folder of the results file does not exist",
                             param="--gradescope", found=text)
    if not (os.path.exists(target) and not os.path.isfile(target)) \
            and not os.access(folder, os.W_OK):
        raise ParameterError("the folder of the results file cannot be written",
                             param="--gradescope", found=text)
    return target


def _write_results(path, text):
    """Write the results file: a regular file (or a new one) is replaced
    atomically (a symbolic link is replaced, never followed); a device, a
    pipe or a terminal (``/dev/stdout``, ``/dev/null``) is written in place,
    never replaced (as root, replacing ``/dev/null`` broke the machine)."""
    path = Path(path)
    try:
        st = os.stat(path)
    except OSError:
        st = None
    if st is not None and not stat.S_ISREG(st.st_mode):
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        return
    _write_atomically(path, text)


def _same_folder(a, b) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _imported_from(folder) -> list:
    """Modules of the grader's own process loaded from ``folder`` (``python
    -m avblocks`` run inside a class folder puts it first on the path: a
    submission named ``random.py`` was then imported as the grader's code)."""
    out = []
    for name, mod in list(sys.modules.items()):
        if "." in name:
            # a submodule came through its package, not through the folder
            # on the path (a test run imported src.avblocks.labs.templates.*
            # by its package names): it shadows nothing a student could name
            continue
        f = getattr(mod, "__file__", None)
        if isinstance(f, str) and _same_folder(os.path.dirname(os.path.abspath(f)), folder):
            out.append(name)
    return sorted(out)


def _keep_off_the_path(folder):
    """Refuse to grade a folder the grader imported code from, and take it
    off the grader's path so that nothing is imported from it later."""
    shadow = _imported_from(folder)
    if shadow:
        raise ParameterError(
            f"the grader itself imported {', '.join(shadow)} from the folder it grades "
            f"(python -m avblocks puts the current folder first on its path): run the "
            f"`avblocks` command, or `python -P -m avblocks`, inside a class folder",
            param="path", found=str(folder))
    sys.path[:] = [p for p in sys.path if not _same_folder(p or ".", folder)]


def _write_atomically(path, text):
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=".results-", dir=str(path.parent))
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def cmd_check(args):
    lab = get(args.number)
    path = Path(args.path)
    if path.is_dir():
        files = sorted(p for p in path.glob("*.py") if not p.name.startswith("."))
        if not files:
            raise ParameterError("no submission in the folder", param="path",
                                 expected="a folder holding .py files", found=str(path))
        if args.student is not None:
            raise ParameterError("--student names one student", param="--student",
                                 expected="one file (a folder derives each file's seed from "
                                          "--seed and its name)", found=str(path))
        if args.gradescope:
            raise ParameterError("--gradescope writes the results of one submission",
                                 param="--gradescope", expected="a file, not a folder",
                                 found=str(path))
    elif path.exists() or path.is_symlink():
        files = [path]          # not a regular file (a FIFO...): read_submission says so
    else:
        raise ParameterError("no such file or folder", param="path",
                             expected="a .py file or a folder of them", found=str(path))
    results = _results_target(args.gradescope) if args.gradescope is not None else None
    folder = path if path.is_dir() else path.absolute().parent
    _keep_off_the_path(folder)
    extra = []
    if args.extra_checks:
        if _same_folder(args.extra_checks, folder):
            raise ParameterError(
                "the extra checks' folder is the folder of the submissions: its files "
                "would be imported into the grader as the instructor's trusted code",
                param="--extra-checks", expected="a folder of the instructor's own",
                found=args.extra_checks)
        from .extra import load_extra
        extra = load_extra(args.extra_checks, lab)
    if args.student is not None:
        seeds = [seed_for("avblocks lab", "student", args.student)]
    elif args.seed is not None and path.is_dir():
        seeds = [seed_for("avblocks lab", args.seed, f.name) for f in files]
    else:
        seeds = [args.seed] * len(files)
    t0 = time.monotonic()
    kw = {"timeout": args.timeout, "memory_mb": args.memory, "extra": extra}
    try:
        if path.is_dir():
            reports = grade_all(lab, files, seeds=seeds, **kw)
        else:
            reports = [run_checks(lab, files[0], seed=seeds[0], **kw)]
    except GraderTampered as e:
        raise ParameterError(str(e), param="path") from None
    status = 0 if all(r.passed for r in reports) else 1
    if results is not None:
        doc = gradescope(reports[0], execution_time=time.monotonic() - t0)
        try:
            _write_results(results, json.dumps(doc, indent=1) + "\n")
        except OSError as e:
            status = 2
            print(f"avblocks: error: in parameter '--gradescope': the results file could not "
                  f"be written ({e.strerror or e}; found {_shown(str(results))}); the "
                  f"results follow", file=sys.stderr)
    if args.json:
        doc = reports[0].as_dict() if not path.is_dir() else [r.as_dict() for r in reports]
        print(json.dumps(doc, indent=1))
    elif args.csv:
        w = csv.writer(sys.stdout, lineterminator="\n")
        w.writerow(CSV_COLUMNS)
        for r in reports:
            w.writerow(csv_row(r))
    elif not path.is_dir():
        print(reports[0].text())
        _print_unset(reports)
    else:
        width = max(len(_shown(Path(r.file).name)) for r in reports)
        print(f"lab {lab.number}: {len(reports)} submissions in {_shown(str(path))}")
        for r in reports:
            ok, total = r.score
            got, most = r.points
            pts = "" if most == total else f" ({got:g}/{most:g} points)"
            first = next((f"{c.name}: {c.message}" for c in r.checks if not c.passed), "")
            print(f"  {_shown(Path(r.file).name):{width}s}  {'PASS' if r.passed else 'FAIL'}  "
                  f"{ok}/{total}{pts}" + (f"  {first[:100]}" if first else ""))
        good = sum(r.passed for r in reports)
        print(f"{good} of {len(reports)} submissions pass every check")
        _print_unset(reports)
    return status


def _print_unset(reports):
    """One line naming the sandbox's limits this platform could not set."""
    unset = {}
    for r in reports:
        for k, v in r.limits.items():
            if v.startswith("not "):
                unset[k] = v
    if unset:
        print("sandbox: " + "; ".join(f"{k} {v}" for k, v in unset.items()))


#: the CSV columns with what each holds (for the docs)
CSV_DOC = CSV_HELP
