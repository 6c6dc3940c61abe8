"""The lab course: exercises whose checks grade themselves.

Each lab (``docs/labs/labN.md``) has a template the student copies with
``avblocks lab start N`` (a Python file with the block or law to write, its
ports already declared) and checks that ``avblocks lab check N FILE`` runs
against independent truth: closed forms, the library's own reference
blocks, and properties of the closed loop. The reference solutions live
with the tests (``tests/labs/solutions/``), not here.

    >>> from avblocks.labs import labs
    >>> [lab.number for lab in labs()][:2]
    [1, 2]
"""

from __future__ import annotations

from .grading import Check, CheckResult, Failed, Report, run_checks, run_checks_here
from .registry import Lab, get, labs

__all__ = ["Check", "CheckResult", "Failed", "Lab", "Report", "get", "labs", "run_checks",
           "run_checks_here"]
