"""Running a student's file against a lab's checks, and reporting.

A check is a function of the loaded submission (a module) that returns a
short note when it passes and raises :class:`Failed` with a message naming
the port, the case, what was expected and what was found when it does not.
Anything else the student's code raises inside a check (or while the file
is loaded) is caught and reported as one readable line: the exception, its
message and the line of the student's file it came from. A check never
ends the grader with a traceback.

:func:`run_checks` runs the student's code in a child process (a fresh
``python``, fed the lab over a pipe), so that it cannot hang or corrupt the grader: every check
(and the loading of the file) has a time limit, after which the child is
killed and the check reported as timed out; the child's stdout and stderr
go to the null device (a print cannot break ``--json`` or ``--csv``); and
on Linux/macOS its address space is limited (``RLIMIT_AS``), so a huge
allocation ends as a ``MemoryError`` reported like any other exception.
:func:`run_checks_here` runs the same checks in this process, unguarded.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import os
import sys
import time
import traceback
import uuid
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

_TEMPLATES = Path(__file__).resolve().parent / "templates"


@dataclass(frozen=True)
class Lab:
    """One lab: what ``avblocks lab list`` shows and ``lab check`` runs.

    Parameters
    ----------
    number : int
        The lab's number (``avblocks lab check N``).
    name : str
        Short name; the template is ``templates/lab{number}_{name}.py``.
    title : str
        One line for ``avblocks lab list``.
    names : tuple of str
        What the student's file must define (a block class, a function).
    checks : list of (str, callable)
        ``(name, check(module) -> note)``, run in order.
    """

    number: int
    name: str
    title: str
    names: tuple = ()
    checks: list = field(default_factory=list, compare=False)

    @property
    def template(self) -> Path:
        """The template file (copied by ``avblocks lab start``)."""
        return _TEMPLATES / f"lab{self.number}_{self.name}.py"


class Failed(Exception):
    """A check's verdict: the student's code ran but gave the wrong answer."""


@dataclass
class CheckResult:
    """One check of one submission."""

    name: str
    passed: bool
    message: str = ""


@dataclass
class Report:
    """Every check of one submission."""

    lab: int
    file: str
    checks: list[CheckResult] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return bool(self.checks) and all(c.passed for c in self.checks)

    @property
    def score(self) -> tuple[int, int]:
        return sum(c.passed for c in self.checks), len(self.checks)

    def as_dict(self) -> dict:
        ok, total = self.score
        return {"lab": self.lab, "file": self.file, "passed": self.passed,
                "checks_passed": ok, "checks_total": total,
                "checks": [asdict(c) for c in self.checks]}

    def text(self) -> str:
        ok, total = self.score
        lines = [f"lab {self.lab}: {self.file}"]
        for c in self.checks:
            mark = "PASS" if c.passed else "FAIL"
            msg = c.message.replace("\n", "\n        ")
            lines.append(f"  {mark}  {c.name}" + (f": {msg}" if msg else ""))
        lines.append(f"{ok} of {total} checks passed" + ("" if ok == total else
                                                         "; see the FAIL lines above"))
        return "\n".join(lines)


def where_in(path, exc: BaseException) -> str:
    """`` (line N of FILE, in FUNC)`` for the deepest frame of ``exc`` in the
    student's file, or ``""``."""
    path = str(Path(path).resolve())
    spot = ""
    for fr in traceback.extract_tb(exc.__traceback__):
        try:
            same = str(Path(fr.filename).resolve()) == path
        except (OSError, ValueError):
            same = False
        if same:
            spot = f" (line {fr.lineno} of {Path(path).name}, in {fr.name})"
    return spot


def describe(exc: BaseException, path) -> str:
    """One line for an exception raised by the student's code."""
    kind = type(exc).__name__
    msg = " ".join(str(exc).split()) or "(no message)"
    spot = where_in(path, exc)
    if isinstance(exc, NotImplementedError):
        return f"not written yet: NotImplementedError: {msg}{spot}"
    if not spot:
        return f"the check could not use what your code returned: {kind}: {msg}"
    return f"your code raised {kind}: {msg}{spot}"


def load(path):
    """Execute the student's file as a fresh module; (module, None) or
    (None, message). Its prints are swallowed (they would mix with the
    report, and break ``--json``)."""
    path = Path(path)
    if not path.is_file():
        return None, f"no such file: {path}"
    name = f"avblocks_lab_submission_{uuid.uuid4().hex}"
    try:
        spec = importlib.util.spec_from_file_location(name, path)
        mod = importlib.util.module_from_spec(spec)
        with contextlib.redirect_stdout(io.StringIO()):
            spec.loader.exec_module(mod)
    except KeyboardInterrupt:
        raise
    except BaseException as e:      # noqa: BLE001 -- the student's code: report, never crash
        if isinstance(e, SyntaxError):
            return None, f"the file does not parse: SyntaxError: {e.msg} (line {e.lineno})"
        return None, f"loading the file: {describe(e, path)}"
    finally:
        sys.modules.pop(name, None)
    return mod, None


#: the default time limit of one check of a student's file [s]
DEFAULT_TIMEOUT = 60.0
#: the default limit of the child's address space [MiB] (``RLIMIT_AS``)
DEFAULT_MEMORY_MB = 4096
#: how long the child may take to start and import avblocks before the
#: first limit starts counting [s] (not the student's time)
STARTUP_ALLOWANCE = 300.0


def run_checks_here(lab, path, emit=None) -> Report:
    """Load ``path`` and run every check of ``lab`` on it in this process
    (no time or memory limit: :func:`run_checks` is the guarded form).

    ``emit(kind, value)``, when given, is told ``("start", check name)``
    before each check (``"load"`` first) and ``("result", CheckResult)``
    after it."""
    emit = emit or (lambda kind, value: None)
    report = Report(lab=lab.number, file=str(path))

    def add(result):
        report.checks.append(result)
        emit("result", result)

    emit("start", "load")
    mod, err = load(path)
    if mod is None:
        add(CheckResult("load", False, err))
        return report
    missing = [n for n in lab.names if not hasattr(mod, n)]
    if missing:
        add(CheckResult(
            "load", False, f"the file defines no {', '.join(missing)} (expected: "
            f"{', '.join(lab.names)}, as in the template `avblocks lab start {lab.number}`)"))
        return report
    for name, fn in lab.checks:
        emit("start", name)
        try:
            with np.errstate(all="ignore"), contextlib.redirect_stdout(io.StringIO()):
                note = fn(mod)
            add(CheckResult(name, True, note or ""))
        except Failed as e:
            add(CheckResult(name, False, str(e)))
        except KeyboardInterrupt:
            raise
        except BaseException as e:  # noqa: BLE001 -- the student's code: report, never crash
            add(CheckResult(name, False, _error_message(e, path)))
    return report


def _child():
    """The child process of :func:`run_checks` (``python -c``): reads
    ``(lab, path, memory_mb)`` pickled from stdin, sends its results over
    the stdout it was started with, then points fds 1 and 2 at the null
    device (the student's prints go nowhere) and limits its address space."""
    import pickle
    from multiprocessing.connection import Connection

    lab, path, memory_mb = pickle.load(sys.stdin.buffer)
    conn = Connection(os.dup(1), readable=False)
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    os.dup2(null, 2)
    if memory_mb:
        try:
            import resource
            limit = int(memory_mb) * 2 ** 20
            _, hard = resource.getrlimit(resource.RLIMIT_AS)
            if hard != resource.RLIM_INFINITY:
                limit = min(limit, hard)
            resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
        except (ImportError, ValueError, OSError):   # Windows, or not allowed: no limit
            pass
    conn.send(("ready", None))
    try:
        run_checks_here(lab, path, emit=lambda kind, value: conn.send((kind, value)))
    except KeyboardInterrupt:
        return
    conn.send(("done", None))


def _start_child(lab, path, memory_mb):
    """A ``python -c`` child running :func:`_child` (not multiprocessing:
    its spawn re-imports the caller's ``__main__``, which fails for a script
    read from stdin and re-runs an unguarded script), and the connection its
    results come on."""
    import pickle
    import subprocess
    from multiprocessing.connection import Connection

    src = str(Path(__file__).resolve().parents[2])        # the folder holding avblocks
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([src] + [p for p in (env.get("PYTHONPATH"),) if p])
    proc = subprocess.Popen(
        [sys.executable, "-c", "from avblocks.labs.grading import _child; _child()"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env)
    try:
        proc.stdin.write(pickle.dumps((lab, str(path), memory_mb)))
        proc.stdin.close()
    except OSError:
        pass
    return proc, Connection(os.dup(proc.stdout.fileno()), writable=False)


def run_checks(lab, path, *, timeout=DEFAULT_TIMEOUT, memory_mb=DEFAULT_MEMORY_MB) -> Report:
    """Load ``path`` and run every check of ``lab`` on it, in a child process.

    Parameters
    ----------
    lab : Lab
        The lab whose checks run.
    path : str or Path
        The student's file.
    timeout : float or None
        Seconds allowed to loading the file and to each check (``None`` or 0:
        no limit). A check that runs longer is stopped (the child is killed)
        and fails with ``timed out after ... s in check '...'``; the checks
        after it are reported as not run.
    memory_mb : int or None
        The child's address-space limit in MiB (``RLIMIT_AS``, where the
        platform has it; ``None`` or 0: no limit). A larger allocation raises
        ``MemoryError`` in the student's code, reported like any exception.

    Returns
    -------
    Report
        Every check's verdict. The child's prints are discarded.
    """
    timeout = float(timeout) if timeout else None
    report = Report(lab=lab.number, file=str(path))
    proc, recv = _start_child(lab, path, memory_mb)
    current, started = None, False
    deadline = time.monotonic() + STARTUP_ALLOWANCE
    try:
        while True:
            left = None if (started and timeout is None) else max(0.0, deadline - time.monotonic())
            if not recv.poll(left):
                _stop(proc)
                if not started:
                    report.checks.append(CheckResult("load", False, (
                        f"the grader's child process did not start within "
                        f"{STARTUP_ALLOWANCE:g} s")))
                else:
                    _timed_out(report, lab, current, timeout)
                break
            try:
                kind, value = recv.recv()
            except (EOFError, OSError):
                try:
                    code = proc.wait(5)
                except Exception:      # noqa: BLE001 -- still running: stopped below
                    code = None
                _died(report, lab, current, code)
                break
            if kind == "ready":
                started = True
            elif kind == "start":
                current = value
                if timeout is not None:
                    deadline = time.monotonic() + timeout
            elif kind == "result":
                if "MemoryError" in value.message and memory_mb:
                    value.message += (f" (the grader allows {int(memory_mb)} MiB: "
                                      f"--memory)")
                report.checks.append(value)
            else:                                            # done
                break
    finally:
        recv.close()
        proc.stdout.close()
        try:
            proc.wait(5)
        except Exception:              # noqa: BLE001 -- still running: stop it
            pass
        _stop(proc)
    return report


def _stop(proc):
    if proc.poll() is None:
        proc.kill()
    proc.wait()


def _not_run(report, lab, after, why):
    done = {c.name for c in report.checks}
    if after == "load":
        return
    for name, _ in lab.checks:
        if name not in done:
            report.checks.append(CheckResult(name, False, f"not run: {why}"))


def _timed_out(report, lab, current, timeout):
    where = "while loading the file" if current == "load" else f"in check '{current}'"
    report.checks.append(CheckResult(current, False, (
        f"timed out after {timeout:g} s {where} of lab {lab.number}: the "
        f"check was stopped (an endless loop, or a step far too slow?); "
        f"raise the limit with --timeout SECONDS")))
    _not_run(report, lab, current, f"check '{current}' timed out")


def _died(report, lab, current, code):
    how = (f"signal {-code}" if code is not None and code < 0 else f"exit status {code}")
    report.checks.append(CheckResult(current or "load", False, (
        f"the process running your code ended ({how}) in check '{current}' of lab "
        f"{lab.number}: a call to os._exit, a crash in compiled code, or out of memory")))
    _not_run(report, lab, current, f"the process ended in check '{current}'")


def _error_message(e, path) -> str:
    from ..core.errors import AvError
    cause = e.__cause__ or e.__context__
    if isinstance(e, AvError) and cause is not None and not isinstance(cause, AvError):
        # the simulator caught the student's exception and named the block
        what = "not written yet" if isinstance(cause, NotImplementedError) else \
            "your code raised an error"
        return (f"{what} while the diagram ran: {' '.join(str(e).split())}"
                f"{where_in(path, cause)}")
    if isinstance(e, AvError):
        # the library's own message names block, port, expected and found
        return f"avblocks refused it: {' '.join(str(e).split())}{where_in(path, e)}"
    return describe(e, path)


# ------------------------------------------------------------ helpers for checks
def fmt(a, digits=4) -> str:
    """A short text for a number or an array."""
    a = np.asarray(a, dtype=float)
    return np.array2string(np.round(a, digits), separator=", ", max_line_width=200,
                           threshold=12)


def compare(port, expected, found, *, atol, case="", rtol=0.0):
    """Raise :class:`Failed` naming the port, the worst agent (row), the
    case, and expected against found, unless they agree."""
    expected = np.asarray(expected, dtype=float)
    try:
        found = np.asarray(found, dtype=float)
    except (TypeError, ValueError) as e:
        raise Failed(f"port `{port}`{case}: found a value that is not numbers ({e})") from None
    if found.shape != expected.shape:
        raise Failed(f"port `{port}`{case}: shape {found.shape}, expected {expected.shape}")
    if not np.all(np.isfinite(found)):
        bad = np.argwhere(~np.isfinite(found))[0]
        raise Failed(f"port `{port}`{case}: NaN or inf at index {tuple(int(i) for i in bad)}")
    err = np.abs(found - expected) - rtol * np.abs(expected)
    if np.all(err <= atol):
        return float(np.max(np.abs(found - expected))) if found.size else 0.0
    flat = err.reshape(err.shape[0], -1).max(axis=1) if err.ndim > 1 else err
    i = int(np.argmax(flat))
    raise Failed(f"port `{port}`{case}, agent {i}: expected {fmt(expected[i])}, "
                 f"found {fmt(found[i])} (tolerance {atol:g})")


def expect_shape(port, value, shape, case=""):
    """``value`` as a float array of ``shape``, or :class:`Failed` naming the port."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as e:
        raise Failed(f"port `{port}`{case}: found a value that is not numbers ({e})") from None
    if a.shape != tuple(shape):
        raise Failed(f"port `{port}`{case}: shape {a.shape}, expected {tuple(shape)}")
    return a


def check_ports(block, *, inputs=None, outputs=None, states=None):
    """Raise :class:`Failed` when ``block`` does not declare these ports with
    these shapes (``{name: shape}``)."""
    kinds = (("input", inputs, block.input_ports), ("output", outputs, block.output_ports),
             ("continuous state", states, block.continuous_states))
    for kind, want, have in kinds:
        for name, shape in (want or {}).items():
            if name not in have:
                raise Failed(f"{type(block).__name__} declares no {kind} `{name}` "
                             f"(has: {', '.join(have) or 'none'})")
            got = have[name].shape if hasattr(have[name], "shape") else None
            if got is not None and tuple(got) != tuple(shape):
                raise Failed(f"{kind} `{name}` of {type(block).__name__}: shape "
                             f"{tuple(got)}, expected {tuple(shape)}")
    return "declared as in the template"
