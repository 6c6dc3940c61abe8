"""The run guard: the checks every engine makes on a run's arguments before it starts.

Shared by the NumPy engine (:mod:`avblocks.core.run_loop`), the compiled engine
(:mod:`avblocks.core.compiled`) and the live engine (:mod:`avblocks.viz.live`),
so an argument means the same and is refused with the same message whichever
engine runs it: the end time is a whole number of major steps, numbers are
finite, the seed fits 64 bits, parameter overrides and initial values name real
parameters and states with the right shapes, and a log fits in memory.
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np

from .errors import ParameterError

#: Most major steps one run may take (beyond it: refused, not hung).
MAX_STEPS = 10**10


def _seed(seed):
    from .params import integer
    return integer(seed, None, "seed", lo=0, hi=2**64 - 1)


def seed_value(seed):
    """``seed`` as a Python int: a whole number in ``[0, 2**64 - 1]`` (every
    engine's check, and the editor's on the field)."""
    return _seed(seed)


def finite_number(v, name):
    ok = not isinstance(v, (bool, np.bool_, str, bytes))
    f = math.nan
    if ok:
        try:
            f = float(v)
        except (TypeError, ValueError, OverflowError):
            ok = False
    if not (ok and math.isfinite(f)):
        raise ParameterError("must be a finite number", param=name,
                             expected="a number", found=repr(v)[:60])
    return f


def major_step(dt):
    """``dt`` as a float: a major step is a finite number > 0 (every engine's
    check, and the editor's on the field)."""
    try:
        f = float(dt) if not isinstance(dt, (bool, np.bool_, str, bytes)) else math.nan
    except (TypeError, ValueError, OverflowError):
        f = math.nan
    if not (math.isfinite(f) and f > 0):
        raise ParameterError("major step must be a positive number",
                             param="dt", expected="> 0", found=dt)
    return f


def whole_steps(t0, t_final, dt):
    """Number of major steps from ``t0`` to ``t_final``; a
    :class:`ParameterError` unless ``t_final - t0`` is a whole number of
    steps ``dt`` (within 1e-9 of a step): a run never stops silently short
    of, or past, the time asked for."""
    span = t_final - t0
    if span < 0:
        raise ParameterError("t_final must be >= t0", param="t_final",
                             expected=f">= {t0:g}", found=t_final)
    steps = span / dt
    if not steps <= MAX_STEPS:
        raise ParameterError(f"the run would take {steps:.3g} major steps",
                             param="dt", expected=f"<= {MAX_STEPS:.0e} steps",
                             found=f"(t_final - t0) / dt = {steps:.3g}",
                             hint="a larger dt or a shorter run")
    n = int(round(steps))
    if abs(steps - n) > 1e-9 * max(1.0, steps):
        lo, hi = math.floor(steps), math.ceil(steps)
        if steps < 1:
            what, expected = ("dt is longer than the whole run",
                              f"t_final = t0 + k*dt with k >= 1, e.g. {t0 + dt:.10g}")
        else:
            what = "t_final - t0 is not a whole number of major steps"
            expected = f"t0 + k*dt, e.g. {t0 + lo * dt:.10g} or {t0 + hi * dt:.10g}"
        raise ParameterError(
            what, param="t_final", expected=expected,
            found=f"t_final={t_final:g} with dt={dt:g} ({steps:.6g} steps)",
            hint="change t_final, or pick a dt that divides t_final - t0")
    return n


def log_every_that_fits(per_sample, nsteps, max_log_bytes):
    """The smallest decimation whose log (``nsteps // k + 1`` samples of
    ``per_sample`` bytes) fits in ``max_log_bytes``, or None."""
    samples = int(max_log_bytes // max(int(per_sample), 1))
    if samples < 2:
        return None
    return max(1, math.ceil(nsteps / (samples - 1)))


def default_log(compiled):
    """Outputs logged when the user names none: every ``pose``/``position``
    output, else every output of the diagram."""
    refs = [f"{n}.{o}" for n, b in zip(compiled.names, compiled.blocks)
            for o in b._outputs if o in ("pose", "position")]
    if not refs:
        refs = [f"{n}.{o}" for n, b in zip(compiled.names, compiled.blocks)
                for o in b._outputs]
    return refs


def initial_values(compiled, x0, runs=None):
    """Checked initial values ``({(block index, state): array}, batched)``
    from ``{"block.state": value}``. With ``runs`` (an ensemble), a value of
    shape ``(runs, *shape)`` is one per run and its key is in ``batched``."""
    out, batched = {}, set()
    if x0 is None:
        return out, batched
    if not isinstance(x0, dict):
        raise ParameterError("x0 must be a dict {'block.state': value}", param="x0",
                             found=type(x0).__name__)
    for path, v in x0.items():
        bpath, _, nm = str(path).rpartition(".")
        i = compiled.index(bpath) if bpath else compiled.index(str(path))
        b = compiled.blocks[i]
        if nm not in b._init or nm in b._random:
            raise ParameterError("no such state", block=bpath, param=nm,
                                 expected=sorted(set(b._init) - b._random), found=nm)
        old = b._init[nm]
        try:
            a = np.array(v, dtype=old.dtype)
        except (TypeError, ValueError):
            raise ParameterError("initial value must be numeric", block=bpath,
                                 param=nm, found=repr(v)[:60]) from None
        if runs is not None and a.shape == (runs, *old.shape):
            batched.add((i, nm))
        elif a.shape != old.shape:
            raise ParameterError("initial value has the wrong shape", block=bpath,
                                 param=nm, expected=old.shape if runs is None else
                                 f"{old.shape} or {(runs, *old.shape)}", found=a.shape)
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise ParameterError("initial value must be finite", block=bpath, param=nm)
        out[(i, nm)] = a
    return out, batched


def _param_binding(compiled, params):
    """A :class:`bound_parameters` for ``{"block.name": value}`` (validated)."""
    from .params import bound_parameters
    if params is None:
        return bound_parameters([])
    if not isinstance(params, dict):
        raise ParameterError("params must be a dict {'block.name': value}",
                             param="params", found=type(params).__name__)
    per_block = {}
    for path, v in params.items():
        i, name = compiled.param_index(path)
        blk = compiled.blocks[i]
        per_block.setdefault(i, (blk, {}))[1][name] = \
            blk._params[name].validate(v, compiled.names[i])
    return bound_parameters(list(per_block.values()))


def in_notebook() -> bool:
    """Whether this process is a Jupyter kernel (an IPython ZMQ shell)."""
    ipython = sys.modules.get("IPython")
    if ipython is None:
        return False
    try:
        shell = ipython.get_ipython()
    except Exception:  # noqa: BLE001 - an odd IPython: no notebook
        return False
    return type(shell).__name__ == "ZMQInteractiveShell"


def _progress_wanted(progress):
    """``progress=None`` shows a bar in a terminal and in Jupyter, not in CI
    or when stderr goes to a file."""
    if progress is not None:
        return bool(progress)
    if os.environ.get("CI"):
        return False
    return in_notebook() or sys.stderr.isatty()


def progress_bar(total):
    """A progress bar over ``total`` steps: a notebook widget in Jupyter
    (``tqdm.auto``, when ipywidgets is installed), a text bar otherwise."""
    if in_notebook():
        from tqdm.auto import tqdm
    else:
        from tqdm import tqdm
    return tqdm(total=total, unit="step", leave=False)
