"""The lab course: exercises whose checks grade themselves.

Each lab (``docs/labs/labN.md``) has a template the student copies with
``avblocks lab start N`` (a Python file with the block or law to write, its
ports already declared) and checks that ``avblocks lab check N FILE`` runs
against independent truth: closed forms, the library's own reference
blocks, and properties of the closed loop. The reference solutions live
with the tests (``tests/labs/solutions/``), not here.

The grader is a security boundary (:mod:`avblocks.labs.grading`): the
student's code runs in a separate, limited process that only computes
(:mod:`~avblocks.labs.sandbox`, :mod:`~avblocks.labs.oscalls`) and answers
over a data-only channel (:mod:`~avblocks.labs.wire`); the checks, the
expected values and the verdicts stay in the grader, which calls the
student's functions and blocks through proxies (:mod:`~avblocks.labs.remote`).
A new lab is a module, a template and tests: see
:mod:`avblocks.labs.grading` and docs/labs/index.md, "Adding a lab".

    >>> from avblocks.labs import labs
    >>> [lab.number for lab in labs()][:2]
    [1, 2]
"""

from __future__ import annotations

from .grading import Check, CheckResult, Failed, Report, run_checks, run_checks_here
from .registry import Lab, get, labs

__all__ = ["Check", "CheckResult", "Failed", "Lab", "Report", "get", "labs", "run_checks",
           "run_checks_here"]
