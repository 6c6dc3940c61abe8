"""What grading costs: each lab's reference solution through ``run_checks``.

Prints one row per lab: the wall time of ``run_checks`` and the CPU time
of the grader and of its child processes (the student's process, its
supervisor, lab 6's emulator) it took. Runs with whatever avblocks is on
the path, so the same script measures an older grader (issue 46: the
checks in the student's process, results pickled back) against the
current one (the student's process only computes; closed loops are
simulated by the grader, which calls the student's block step by step).

    python benchmarks/labs_grader.py [--labs 1,2,3] [--repeat 2]
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

from avblocks.labs import get, run_checks

SOLUTIONS = Path(__file__).resolve().parents[1] / "tests" / "labs" / "solutions"


def measure(number):
    lab = get(number)
    r0, c0, t0 = (resource.getrusage(resource.RUSAGE_SELF),
                  resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter())
    rep = run_checks(lab, SOLUTIONS / lab.template.name)
    wall = time.perf_counter() - t0
    r1, c1 = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_self = (r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime)
    cpu_kids = (c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime)
    return wall, cpu_self, cpu_kids, rep.passed, len(rep.checks)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--labs", default="1,2,3,4,5,6")
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args(argv)
    print(f"{'lab':>3}  {'checks':>6}  {'wall [s]':>8}  {'grader CPU [s]':>14}  "
          f"{'children CPU [s]':>16}  passed")
    for n in (int(x) for x in args.labs.split(",")):
        rows = [measure(n) for _ in range(args.repeat)]
        wall, cs, ck, ok, k = min(rows)
        print(f"{n:>3}  {k:>6}  {wall:8.2f}  {cs:14.2f}  {ck:16.2f}  {ok}")


if __name__ == "__main__":
    main()
