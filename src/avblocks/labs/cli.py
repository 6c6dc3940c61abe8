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
import sys
import tempfile
import time
from pathlib import Path

from ..core.errors import ParameterError
from .grading import DEFAULT_MEMORY_MB, DEFAULT_TIMEOUT, GraderTampered, grade_all, run_checks
from .registry import get, labs
from .remote import seed_for
from .report import CSV_COLUMNS, CSV_HELP, csv_row, gradescope


def _seconds(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of seconds: {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(
            f"must be a finite number of seconds > 0, got {text!r}")
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
                         f"{DEFAULT_TIMEOUT:g}; a finite number > 0); a check past it fails "
                         f"as timed out")
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


def _shown(name) -> str:
    """A file name as one line of printable text (a name is the student's)."""
    return "".join(c if c.isprintable() else "?" for c in name)


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
    elif path.is_file() or path.is_symlink():
        files = [path]
    else:
        raise ParameterError("no such file or folder", param="path",
                             expected="a .py file or a folder of them", found=str(path))
    if args.gradescope and not Path(args.gradescope).resolve().parent.is_dir():
        raise ParameterError("the folder of the results file does not exist",
                             param="--gradescope", found=args.gradescope)
    extra = []
    if args.extra_checks:
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
    if args.gradescope:
        doc = gradescope(reports[0], execution_time=time.monotonic() - t0)
        _write_atomically(args.gradescope, json.dumps(doc, indent=1) + "\n")
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
    return 0 if all(r.passed for r in reports) else 1


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
