"""An instructor's hidden checks: ``avblocks lab check N ... --extra-checks DIR``.

Every ``*.py`` file of ``DIR`` (not starting with ``_`` or ``.``) is a
module of checks, written like a lab's own (see
:mod:`avblocks.labs.grading`), that says which labs it is for and what its
checks are worth::

    # extra/lab1_more.py
    import numpy as np
    from avblocks.labs import Check, Failed
    from avblocks.labs.grading import compare

    LAB = 1                                  # or LABS = (1, 2)

    def standing_still(sub):
        cmd = sub.wheels_to_cmd(np.zeros((3, 2)), 0.05, 0.2)
        compare("cmd (wheels_to_cmd)", np.zeros((3, 2)), cmd, atol=0.0,
                case=" with both wheels still")
        return "no motion without wheel speed"

    CHECKS = [Check("wheels still, robot still", standing_still, points=2,
                    visibility="after_published")]

The files are the instructor's, trusted code: they are imported into the
grader's process (never into the student's), and their checks reach the
student's code only as the lab's checks do, through the
:class:`~avblocks.labs.remote.Submission` handed to them. They run after
the lab's own checks, with their points; on Gradescope a check's
``visibility`` decides when students see it (``after_published``: when the
grades are published).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from ..core.errors import ParameterError
from .grading import as_check


def load_extra(folder, lab) -> list:
    """The extra checks in ``folder`` for ``lab``, in file-name order;
    :class:`ParameterError` naming the file for one that does not load or
    does not declare ``LAB``/``LABS`` and ``CHECKS`` properly. Every file
    is first read and parsed, none run: a file without a top-level ``LAB``
    or ``LABS`` is refused before any of the folder is imported."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ParameterError("no such folder", param="--extra-checks",
                             expected="a folder of check modules", found=str(folder))
    out = []
    taken = {c.name for c in lab.all_checks()}
    paths = [p for p in sorted(folder.glob("*.py")) if not p.name.startswith(("_", "."))]
    for path in paths:                     # before any of them runs
        _looks_like_checks(path)
    for path in paths:
        mod = _import(path)
        labs = getattr(mod, "LABS", None)
        if labs is None:
            labs = (getattr(mod, "LAB", None),)
        try:
            numbers = {int(n) for n in labs}
        except (TypeError, ValueError):
            raise ParameterError("LAB must be a lab's number (or LABS a tuple of them)",
                                 param="--extra-checks", found=f"{path.name}: {labs!r}"
                                 ) from None
        if lab.number not in numbers:
            continue
        entries = getattr(mod, "CHECKS", None)
        if not isinstance(entries, (list, tuple)) or not entries:
            raise ParameterError("a check module must define CHECKS, a list of Check "
                                 "(or (name, fn[, points]))", param="--extra-checks",
                                 found=path.name)
        for e in entries:
            try:
                c = as_check(e)
            except (TypeError, ValueError) as err:
                raise ParameterError(f"a bad entry in CHECKS: {err}", param="--extra-checks",
                                     found=path.name) from None
            if c.name in taken:
                raise ParameterError(f"check {c.name!r} is named twice (the lab's checks and "
                                     f"the extra ones need different names)",
                                     param="--extra-checks", found=path.name)
            taken.add(c.name)
            out.append(c)
    return out


def _looks_like_checks(path):
    """Refuse, without running it, a file that cannot be a module of checks:
    not readable text, or no top-level ``LAB = ...`` / ``LABS = ...`` (a
    folder of students' files given by mistake, a download folder: those
    were imported, and so run, as the instructor's trusted code)."""
    import ast

    from .grading import read_submission
    text, err = read_submission(path)
    if err:
        raise ParameterError(f"not a check module: {err} (nothing of the folder was run)",
                             param="--extra-checks", found=path.name)
    try:
        tree = ast.parse(text, filename=path.name)
    except (SyntaxError, ValueError, RecursionError, MemoryError) as e:
        raise ParameterError(f"the check module does not parse ({type(e).__name__}: "
                             f"{str(e)[:120]}; nothing of the folder was run)",
                             param="--extra-checks", found=path.name) from None
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, ast.AnnAssign) else []
        if any(isinstance(t, ast.Name) and t.id in ("LAB", "LABS") for t in targets):
            return
    raise ParameterError("not a check module: it assigns no LAB (or LABS) at its top level; "
                         "nothing of the folder was run (is it the folder of the "
                         "submissions?)", param="--extra-checks", found=path.name)


def _import(path):
    name = f"avblocks_lab_extra_{abs(hash(str(path.resolve())))}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ParameterError("not a Python module", param="--extra-checks", found=path.name)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    try:
        spec.loader.exec_module(mod)
    except Exception as e:  # noqa: BLE001 - the instructor's file: say what and where
        sys.modules.pop(name, None)
        raise ParameterError(f"the check module failed to load: {type(e).__name__}: {e}",
                             param="--extra-checks", found=path.name) from None
    return mod
