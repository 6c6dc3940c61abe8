"""``avblocks lab``: list the labs, start one, check a submission or a folder.

    avblocks lab list [--json]
    avblocks lab start N [--force]          # copies the template here
    avblocks lab check N FILE [--json]      # exit 0 only when every check passes
    avblocks lab check N DIR [--csv | --json]
        [--timeout SECONDS] [--memory MIB]

The student's code runs in a child process: each check (and loading the
file) may take ``--timeout`` seconds (default 60; 0: no limit), after which
it is stopped and reported as timed out; its address space is limited to
``--memory`` MiB (default 4096; 0: no limit) where the platform allows;
what it prints is discarded.

Exit status: 0 every check passed; 1 a check failed, timed out or the
student's code ended the process (for a folder: in at least one
submission); 2 bad input (no such lab, file or folder, a file
that ``start`` would overwrite).
"""

from __future__ import annotations

import csv
import json
import shutil
import sys
from pathlib import Path

from ..core.errors import ParameterError
from .grading import DEFAULT_MEMORY_MB, DEFAULT_TIMEOUT, run_checks
from .registry import get, labs


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
                     help="one CSV row per submission (file, passed, score, failed checks)")
    ch.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT, metavar="SECONDS",
                    help=f"time limit of each check of a submission (default "
                         f"{DEFAULT_TIMEOUT:g}; 0: none); a check past it fails as timed out")
    ch.add_argument("--memory", type=int, default=DEFAULT_MEMORY_MB, metavar="MIB",
                    help=f"address-space limit of the process running the student's code "
                         f"(default {DEFAULT_MEMORY_MB}; 0: none)")
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


def cmd_check(args):
    lab = get(args.number)
    path = Path(args.path)
    if path.is_dir():
        files = sorted(p for p in path.glob("*.py") if not p.name.startswith("."))
        if not files:
            raise ParameterError("no submission in the folder", param="path",
                                 expected="a folder holding .py files", found=str(path))
    elif path.is_file():
        files = [path]
    else:
        raise ParameterError("no such file or folder", param="path",
                             expected="a .py file or a folder of them", found=str(path))
    if args.timeout < 0 or args.memory < 0:
        raise ParameterError("a negative limit", param="--timeout/--memory",
                             expected=">= 0 (0: no limit)",
                             found=f"{args.timeout:g} s, {args.memory} MiB")
    reports = [run_checks(lab, f, timeout=args.timeout, memory_mb=args.memory) for f in files]
    if args.json:
        doc = reports[0].as_dict() if path.is_file() else [r.as_dict() for r in reports]
        print(json.dumps(doc, indent=1))
    elif args.csv:
        w = csv.writer(sys.stdout, lineterminator="\n")
        w.writerow(["file", "lab", "passed", "checks_passed", "checks_total", "failed"])
        for r in reports:
            ok, total = r.score
            w.writerow([Path(r.file).name, r.lab, "yes" if r.passed else "no", ok, total,
                        "; ".join(f"{c.name}: {c.message}" for c in r.checks if not c.passed)])
    elif path.is_file():
        print(reports[0].text())
    else:
        width = max(len(Path(r.file).name) for r in reports)
        print(f"lab {lab.number}: {len(reports)} submissions in {path}")
        for r in reports:
            ok, total = r.score
            first = next((f"{c.name}: {c.message}" for c in r.checks if not c.passed), "")
            print(f"  {Path(r.file).name:{width}s}  {'PASS' if r.passed else 'FAIL'}  "
                  f"{ok}/{total}" + (f"  {first[:100]}" if first else ""))
        good = sum(r.passed for r in reports)
        print(f"{good} of {len(reports)} submissions pass every check")
    return 0 if all(r.passed for r in reports) else 1
