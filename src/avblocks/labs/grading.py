"""Grading a student's file against a lab's checks.

The lab contract
----------------
A lab is a module ``labN_name.py`` beside this one that ends with
``LAB = Lab(N, "name", "title", names=(...), checks=[...])``:

* ``names``: what the student's file must define (classes, functions);
* ``checks``: ``(name, check)`` pairs (or :class:`Check` objects, which add
  points and a visibility), run in order. ``check(sub)`` receives a
  :class:`~avblocks.labs.remote.Submission`: ``sub.MyBlock(...)`` constructs
  the student's block *in the student's process* and returns a proxy block
  to wire into a diagram the check simulates itself; ``sub.my_function(...)``
  calls the student's function there and returns its result as data;
  ``sub.rng(k)`` draws the check's case ``k`` (the fixed case of the lab's
  page without a seed, a per-student case with one). A check returns a
  short note when the student's code is right and raises :class:`Failed`
  naming the port, the case, what was expected and what was found when it
  is not (:func:`compare`, :func:`expect_shape`, :func:`check_ports` do
  that). Compare with independent truth (a closed form, a library block,
  a property of the closed loop), never with the reference solution.

The template is ``templates/labN_name.py`` (the ports declared, the bodies
to write raising ``NotImplementedError``); the reference solution and
wrong solutions live with the tests (``tests/labs/``). See
docs/labs/index.md, "Adding a lab".

The security boundary
---------------------
:func:`run_checks` never imports the student's file: it reads the file
once (a regular file, UTF-8 text, at most :data:`MAX_SOURCE_BYTES`), starts
a :class:`~avblocks.labs.sandbox.Sandbox` and sends it the text. The
expected values, the comparisons and the verdicts stay here. Whatever the
student's code does (raise, loop, exit, crash, print, write garbage into
the channel, fork) becomes one readable line in the report and, for what
ends the process, "not run" for the checks after it; the grader itself
never fails with a traceback.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import stat
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# every module a check needs is loaded before any student's code runs: where
# nothing stops a write into the installation (no Landlock), a module first
# imported during a check could be one the student's process had replaced
from ..core import run_loop as _run_loop  # noqa: F401
from .remote import RESERVED, Failed, Submission, seed_for
from .report import VISIBILITY, CheckResult, Report
from .sandbox import (
    ChannelBroken,
    Died,
    Sandbox,
    SandboxError,
    SandboxLimits,
    StudentRaised,
    TimedOut,
)

_TEMPLATES = Path(__file__).resolve().parent / "templates"

#: the default time limit of loading the file and of each check [s]
DEFAULT_TIMEOUT = 60.0
#: the largest time limit accepted [s]: one day (beyond it the platform's
#: timers and limits overflow; a correct solution failed to start with 1e20)
MAX_TIMEOUT = 86400.0
#: the default limit of the child's address space [MiB] (``RLIMIT_AS``)
DEFAULT_MEMORY_MB = 4096
#: how long the child may take to start and import avblocks before the
#: first limit starts counting [s] (not the student's time)
STARTUP_ALLOWANCE = 300.0
#: the largest submission file read
MAX_SOURCE_BYTES = 1 << 20


@dataclass(frozen=True)
class Check:
    """One check of a lab (or of an instructor's ``--extra-checks``).

    Parameters
    ----------
    name : str
        Shown in the report.
    fn : callable
        ``fn(sub) -> note``; raises :class:`Failed` when the student's code is
        wrong (see the module docstring).
    points : float
        What it is worth (> 0).
    visibility : str
        Gradescope's visibility (``visible``, ``hidden``, ``after_due_date``,
        ``after_published``).
    """

    name: str
    fn: object
    points: float = 1.0
    visibility: str = "visible"

    def __post_init__(self):
        if not (isinstance(self.name, str) and self.name.strip()):
            raise ValueError(f"a check's name is a non-empty text, got {self.name!r}")
        if not callable(self.fn):
            raise ValueError(f"check {self.name!r}: fn is not callable")
        p = self.points
        if isinstance(p, bool) or not isinstance(p, (int, float)) or not (
                math.isfinite(p) and p > 0):
            raise ValueError(f"check {self.name!r}: points must be a finite number > 0, "
                             f"got {p!r}")
        if self.visibility not in VISIBILITY:
            raise ValueError(f"check {self.name!r}: visibility must be one of {VISIBILITY}, "
                             f"got {self.visibility!r}")


def as_check(entry) -> Check:
    """A :class:`Check` from a lab's ``checks`` entry: a Check, ``(name, fn)``
    or ``(name, fn, points)``."""
    if isinstance(entry, Check):
        return entry
    return Check(*entry)


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
    checks : list
        ``(name, check(sub) -> note)`` pairs or :class:`Check` objects, run
        in order.
    """

    number: int
    name: str
    title: str
    names: tuple = ()
    checks: list = field(default_factory=list, compare=False)

    def __post_init__(self):
        clash = RESERVED.intersection(self.names)
        if clash:
            raise ValueError(f"lab {self.number}: {sorted(clash)} are the grader's own names")

    @property
    def template(self) -> Path:
        """The template file (copied by ``avblocks lab start``)."""
        return _TEMPLATES / f"lab{self.number}_{self.name}.py"

    def all_checks(self) -> list[Check]:
        """The checks as :class:`Check` objects."""
        return [as_check(c) for c in self.checks]


# ------------------------------------------------------------------ helpers for checks
def fmt(a, digits=4) -> str:
    """A short text for a number or an array."""
    a = np.asarray(a, dtype=float)
    return np.array2string(np.round(a, digits), separator=", ", max_line_width=200,
                           threshold=12)


def _fmt_pair(expected, found, digits=4):
    """Texts of ``expected`` and ``found`` with enough digits to tell them
    apart (up to 17)."""
    e, f = np.asarray(expected, dtype=float), np.asarray(found, dtype=float)
    d = digits
    while d < 17 and np.array_equal(np.round(e, d), np.round(f, d)) and not np.array_equal(e, f):
        d += 2
    return fmt(e, d), fmt(f, d)


def _low_precision(a) -> bool:
    return isinstance(a, np.ndarray) and a.dtype.kind == "f" and a.dtype.itemsize < 8


def _as_numbers(port, value, case):
    if isinstance(value, (list, tuple)):
        raise Failed(f"port `{port}`{case}: found a {type(value).__name__}, expected an array "
                     f"(xp.stack([...], axis=-1) builds one)")
    try:
        a = np.asarray(value)
        if a.dtype.kind not in "biuf":
            raise TypeError(f"dtype {a.dtype}")
        return a
    except (TypeError, ValueError) as e:
        raise Failed(f"port `{port}`{case}: found a value that is not numbers ({e})") from None


def compare(port, expected, found, *, atol, case="", rtol=0.0):
    """Raise :class:`Failed` naming the port, the worst agent (row), the
    case, and expected against found, unless they agree; a float32 result
    that misses is said to be a dtype problem."""
    expected = np.asarray(expected, dtype=float)
    raw = _as_numbers(port, found, case)
    found = raw.astype(float)
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
    if _low_precision(raw):
        raise Failed(f"port `{port}`{case}: the result is {raw.dtype} (dtype {raw.dtype}), "
                     f"expected float64: {raw.dtype} keeps about "
                     f"{np.finfo(raw.dtype).precision} digits, the check needs {atol:g} "
                     f"(largest error {float(np.max(np.abs(found - expected))):.2g}); compute "
                     f"in float64 (no dtype=np.float32, no .astype(np.float32))")
    e_txt, f_txt = _fmt_pair(expected[i], found[i])
    raise Failed(f"port `{port}`{case}, agent {i}: expected {e_txt}, found {f_txt} "
                 f"(tolerance {atol:g})")


def expect_shape(port, value, shape, case=""):
    """``value`` as a numeric array of ``shape`` (its dtype kept), or
    :class:`Failed` naming the port."""
    a = _as_numbers(port, value, case)
    if a.shape != tuple(shape):
        raise Failed(f"port `{port}`{case}: shape {a.shape}, expected {tuple(shape)}")
    return a


def check_ports(block, *, inputs=None, outputs=None, states=None):
    """Raise :class:`Failed` when ``block`` does not declare these ports with
    these shapes (``{name: shape}``)."""
    cls = getattr(block, "class_name", type(block).__name__)
    kinds = (("input", inputs, block.input_ports), ("output", outputs, block.output_ports),
             ("continuous state", states, block.continuous_states))
    for kind, want, have in kinds:
        for name, shape in (want or {}).items():
            if name not in have:
                raise Failed(f"{cls} declares no {kind} `{name}` "
                             f"(has: {', '.join(have) or 'none'})")
            got = have[name].shape if hasattr(have[name], "shape") else None
            if got is not None and tuple(got) != tuple(shape):
                raise Failed(f"{kind} `{name}` of {cls}: shape "
                             f"{tuple(got)}, expected {tuple(shape)}")
    return "declared as in the template"


# ------------------------------------------------------------------ the submission's text
def read_submission(path) -> tuple[str | None, str | None]:
    """``(text, None)`` for a readable submission, ``(None, why)`` otherwise:
    the file is opened without following a symbolic link, must be a
    regular file of at most :data:`MAX_SOURCE_BYTES` and UTF-8 text."""
    path = Path(path)
    # O_NONBLOCK: opening a FIFO named like a submission must not wait for a
    # writer (a folder holding one hung the grader); checked regular below
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_BINARY", 0) \
        | getattr(os, "O_NONBLOCK", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        return None, f"no such file: {path.name}"
    except OSError as e:
        if path.is_symlink():
            return None, "the file is a symbolic link: submit the .py file itself"
        return None, f"the file cannot be read ({e.strerror})"
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            return None, "not a regular file (a folder, a pipe or a device?)"
        if st.st_size > MAX_SOURCE_BYTES:
            return None, (f"the file holds {st.st_size} bytes, more than a lab's "
                          f"{MAX_SOURCE_BYTES} (is it the right file?)")
        chunks, size = [], 0
        while size <= MAX_SOURCE_BYTES:
            b = os.read(fd, 1 << 16)
            if not b:
                break
            chunks.append(b)
            size += len(b)
        data = b"".join(chunks)
    finally:
        os.close(fd)
    if len(data) > MAX_SOURCE_BYTES:
        return None, f"the file holds more than {MAX_SOURCE_BYTES} bytes"
    if b"\x00" in data:
        return None, ("the file is not Python source text (it holds NUL bytes: a binary "
                      "file, or a notebook or archive saved as .py?)")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        return None, (f"the file is not Python source text: byte {e.start} is not UTF-8 "
                      f"(a binary file, or text saved in another encoding?)")
    return text, None


# ------------------------------------------------------------------ running the checks
class _Runner:
    """One submission's sandbox, as the proxies see it."""

    def __init__(self, sandbox, display_name):
        self.sandbox = sandbox
        self.display_name = display_name

    def request(self, op, deadline, **fields):
        return self.sandbox.request(op, deadline, **fields)


def _where(rec, name) -> str:
    line, func = rec.get("line"), rec.get("func")
    if line is None:
        return ""
    return f" (line {line} of {name}" + (f", in {func})" if func else ")")


def describe(rec, name, *, memory_mb=None) -> str:
    """One line for an error record of the student's process (see
    :func:`avblocks.labs._child.error_record`)."""
    kind, msg, flags = rec["kind"], rec["message"] or "(no message)", rec["flags"]
    where = _where(rec, name)
    if "syntax" in flags:
        return f"the file does not parse: SyntaxError: {msg} (line {rec.get('line')})"
    if "not_implemented" in flags:
        return f"not written yet: NotImplementedError: {msg}{where}"
    if "readonly" in flags:
        what = rec.get("readonly") or "inputs"
        return (f"your code wrote into its {what}{where}: the arrays a block or function "
                f"is handed (inputs, states) are read-only and must not be changed (in a "
                f"diagram they belong to the simulator or to another block); compute a new "
                f"array instead (x = x + dx, xp.where(...), or .copy() first)")
    if "interrupt" in flags:
        return (f"your code raised KeyboardInterrupt{where}: an interrupt stopped it "
                f"(Ctrl-C, or a signal it sent itself); this is not a crash and not memory")
    if "memory" in flags:
        lim = f" (the grader allows {int(memory_mb)} MiB: --memory)" if memory_mb else ""
        return f"your code raised MemoryError: {msg}{where}{lim}"
    if "too_large" in flags:
        return f"your code returned too much: {msg}"
    if "refused" in flags:
        return f"the grader could not call your code: {msg}"
    if "avblocks" in flags:
        cause = rec.get("cause")
        return f"avblocks refused it: {msg}{where or (_where(cause, name) if cause else '')}"
    if not where:
        return f"your code raised {kind}: {msg} (when the grader called it)"
    return f"your code raised {kind}: {msg}{where}"


def _chain(exc):
    seen, out = set(), []
    while exc is not None and id(exc) not in seen and len(out) < 20:
        seen.add(id(exc))
        out.append(exc)
        exc = exc.__cause__ or exc.__context__
    return out


def _explain(exc, name, memory_mb):
    """``(message, fatal)`` for what a check raised: fatal when the
    student's process is gone or cannot be trusted to answer."""
    from ..core.errors import AvError, SimulationError
    chain = _chain(exc)
    for e in chain:
        if isinstance(e, (TimedOut, Died, ChannelBroken)):
            return e, True
    for e in chain:
        if isinstance(e, Failed):
            return str(e), False
    for e in chain:
        if isinstance(e, StudentRaised):
            msg = describe(e.record, name, memory_mb=memory_mb)
            if isinstance(exc, SimulationError):
                where = []
                if exc.block:
                    where.append(f"block '{exc.block}'")
                if exc.time is not None:
                    where.append(f"t = {exc.time:.4g} s")
                msg += " while the diagram ran" + (f" ({', '.join(where)})" if where else "")
            return msg, False
    if isinstance(exc, AvError):
        return f"avblocks refused it: {' '.join(str(exc).split())}", False
    text = " ".join(str(exc).split()) or "(no message)"
    return f"the check could not use what your code returned: {type(exc).__name__}: " \
           f"{text[:300]}", False


def _stopped(report, checks, current, why):
    done = {c.name for c in report.checks}
    for c in checks:
        if c.name not in done and c.name != current:
            report.checks.append(CheckResult(c.name, False, f"not run: {why}", c.points,
                                             c.visibility))


def _fatal_message(err, lab, current, timeout, limits):
    where = "while loading the file" if current == "load" else f"in check '{current}'"
    if isinstance(err, TimedOut):
        return (f"timed out after {timeout:g} s {where} of lab {lab.number}: the check was "
                f"stopped (an endless loop, or a step far too slow?); raise the limit with "
                f"--timeout SECONDS"), f"check '{current}' timed out"
    if isinstance(err, Died):
        code = err.returncode
        sig = -code if code is not None and code < 0 else None
        import signal as _signal
        names = {getattr(_signal, n, None): n for n in ("SIGKILL", "SIGXCPU", "SIGSEGV",
                                                         "SIGBUS", "SIGABRT", "SIGINT",
                                                         "SIGTERM")}
        why = {"SIGKILL": "it was killed: out of memory, or a limit of the grader",
               "SIGXCPU": f"it used up its {limits.cpu_s:g} s of CPU time (the grader's limit)",
               "SIGSEGV": "a crash in compiled code, or a recursion too deep for the C stack",
               "SIGBUS": "a crash in compiled code", "SIGABRT": "a crash in compiled code",
               "SIGINT": "an interrupt (SIGINT) it did not handle",
               "SIGTERM": "a termination signal (SIGTERM)"}.get(names.get(sig)) if sig else None
        why = why or "a call to os._exit, a crash in compiled code, or out of memory"
        return (f"the process running your code ended ({err.status}) {where} of lab "
                f"{lab.number}: {why}"), f"the process ended in check '{current}'"
    return (f"the process running your code broke the grader's channel {where} of lab "
            f"{lab.number}: {err}; nothing it sends is trusted after that"), \
        f"the channel broke in check '{current}'"


@contextlib.contextmanager
def _interrupts():
    """Remember a Ctrl-C (SIGINT) or SIGTERM that lands during a check:
    ``simulate`` keeps what it simulated when interrupted and returns, so
    the grader checks the list after each check and stops (the ``finally``
    blocks kill the student's process and lab 6's emulator)."""
    got: list = []
    if threading.current_thread() is not threading.main_thread():
        yield got
        return

    def handler(signum, frame):
        got.append(signum)
        raise KeyboardInterrupt

    old = {}
    for sig in (signal.SIGINT, getattr(signal, "SIGTERM", None)):
        if sig is None:
            continue
        try:
            old[sig] = signal.signal(sig, handler)
        except (ValueError, OSError):
            pass
    try:
        yield got
    finally:
        for sig, h in old.items():
            with contextlib.suppress(ValueError, OSError):
                signal.signal(sig, h)


def limits_for(timeout, memory_mb, n_checks) -> SandboxLimits:
    """The student's process's limits for ``n_checks`` checks of ``timeout``
    seconds each: ``memory_mb`` of address space, CPU time for all of them."""
    return SandboxLimits(memory_mb=int(memory_mb or 0),
                         cpu_s=max(60.0, float(timeout) * (n_checks + 2)))


def run_checks(lab, path, *, timeout=DEFAULT_TIMEOUT, memory_mb=DEFAULT_MEMORY_MB,
               seed=None, extra=(), source=None, limits=None, on_result=None,
               sandbox=None) -> Report:
    """Grade ``path`` against ``lab``: the student's code runs in a
    :class:`~avblocks.labs.sandbox.Sandbox`, the checks here.

    Parameters
    ----------
    lab : Lab
        The lab whose checks run.
    path : str or Path
        The student's file (its name is what messages quote).
    timeout : float
        Seconds allowed to loading the file and to each check (finite, > 0,
        at most :data:`MAX_TIMEOUT`).
        A check that runs longer is stopped (the student's process is
        killed) and fails with ``timed out after ... s in check '...'``; the
        checks after it are reported as not run. ``None`` or 0 (older
        callers): :data:`DEFAULT_TIMEOUT`.
    memory_mb : int or None
        The address-space limit of the student's process in MiB
        (``RLIMIT_AS`` where the platform has it); ``None`` or 0: none.
    seed : int, optional
        Draw the cases from this seed (``Submission.rng``) instead of the
        lab page's fixed cases.
    extra : sequence of Check
        More checks (an instructor's ``--extra-checks``), run after the lab's.
    source : str, optional
        The file's text, already read (a folder run reads every file first).
    limits : SandboxLimits, optional
        The other limits of the student's process (default
        :class:`SandboxLimits` with ``memory_mb``).
    on_result : callable, optional
        ``on_result(kind, value)``: ``("start", check name)`` before each
        check (``"load"`` first) and ``("result", CheckResult)`` after it.
    sandbox : Sandbox, optional
        A student's process already started (:func:`grade_all` starts the
        next one while a submission is graded, where that is safe); closed
        here.

    Returns
    -------
    Report
        Every check's verdict, with what the grader could set of the limits.
    """
    timeout = float(timeout) if timeout else DEFAULT_TIMEOUT
    if not (math.isfinite(timeout) and 0 < timeout <= MAX_TIMEOUT):
        raise ValueError(f"timeout must be a finite number of seconds > 0 and at most "
                         f"{MAX_TIMEOUT:g}, got {timeout!r}")
    checks = lab.all_checks() + [as_check(c) for c in extra]
    limits = limits or limits_for(timeout, memory_mb, len(checks))
    emit = on_result or (lambda kind, value: None)
    from . import oscalls
    with _interrupts() as interrupted, oscalls.undumpable():
        return _run(lab, path, checks, timeout, memory_mb, seed, source, limits, emit,
                    sandbox, interrupted)


def _run(lab, path, checks, timeout, memory_mb, seed, source, limits, emit, sandbox,
         interrupted):
    report = Report(lab=lab.number, file=str(path), seed=seed)
    name = Path(path).name

    def add(result):
        report.checks.append(result)
        emit("result", result)

    def load_failed(msg):
        add(CheckResult("load", False, _one_line(msg), 0.0))
        for c in checks:
            report.checks.append(CheckResult(c.name, False, "not run: the file did not load",
                                             c.points, c.visibility))

    emit("start", "load")
    if source is None:
        source, err = read_submission(path)
        if err:
            if sandbox is not None:
                sandbox.close()
            load_failed(err)
            return report
    if sandbox is None:
        sandbox = Sandbox(limits)
    runner = _Runner(sandbox, name)
    try:
        if sandbox.run is None:
            sandbox.start()
        try:
            report.limits = sandbox.wait_ready(time.monotonic() + STARTUP_ALLOWANCE)
        except TimedOut:
            load_failed(f"the grader's child process did not start within "
                        f"{STARTUP_ALLOWANCE:g} s")
            return report
        except (Died, ChannelBroken) as e:
            load_failed(f"the grader's child process failed to start ({e})")
            return report
        try:
            found = sandbox.request("load", time.monotonic() + timeout, source=source,
                                    filename=str(Path(path).resolve()), names=list(lab.names))
        except StudentRaised as e:
            load_failed("loading the file: " + describe(e.record, name, memory_mb=memory_mb)
                        if "syntax" not in e.record["flags"] else
                        describe(e.record, name))
            return report
        except SandboxError as e:
            msg, _ = _fatal_message(e, lab, "load", timeout, limits)
            load_failed(msg)
            return report
        names = found.get("names", {}) if isinstance(found, dict) else {}
        names = {k: v for k, v in names.items() if k in lab.names} if isinstance(names, dict) \
            else {}
        missing = [n for n in lab.names if n not in names]
        if missing:
            load_failed(f"the file defines no {', '.join(missing)} (expected: "
                        f"{', '.join(lab.names)}, as in the template `avblocks lab start "
                        f"{lab.number}`)")
            return report
        for check in checks:
            emit("start", check.name)
            sub = Submission(runner, names, seed=seed, check=check.name,
                             deadline=time.monotonic() + timeout)
            try:
                with np.errstate(all="ignore"):
                    note = check.fn(sub)
                if interrupted:
                    raise KeyboardInterrupt
                add(CheckResult(check.name, True, _one_line(note or ""), check.points,
                                check.visibility))
            except KeyboardInterrupt:
                raise
            except BaseException as e:  # noqa: BLE001 - every failure is one line
                if interrupted:
                    raise KeyboardInterrupt from None
                msg, fatal = _explain(e, name, memory_mb)
                if fatal:
                    text, why = _fatal_message(msg, lab, check.name, timeout, limits)
                    add(CheckResult(check.name, False, text, check.points, check.visibility))
                    _stopped(report, checks, check.name, why)
                    break
                add(CheckResult(check.name, False, _one_line(msg), check.points,
                                check.visibility))
    finally:
        sandbox.close()
    return report


def _one_line(text) -> str:
    from .sandbox import _ANSI
    text = "".join(c if c.isprintable() else " " for c in _ANSI.sub("", str(text)))
    text = " ".join(text.split())
    return text if len(text) <= 2000 else text[:1997] + "..."


def run_checks_here(lab, path, emit=None) -> Report:
    """Kept for older scripts: the same as :func:`run_checks` (the student's
    code no longer runs in the grader's process, whatever the caller asks),
    with ``emit(kind, value)`` told ``("start", check name)`` and
    ``("result", CheckResult)`` as the checks go."""
    return run_checks(lab, path, on_result=emit)


# ------------------------------------------------------------------ a folder
def _snapshot(folder) -> dict:
    """``{name: (size, mtime_ns, inode)}`` of the files directly in ``folder``."""
    out = {}
    try:
        with os.scandir(folder) as it:
            for e in it:
                try:
                    st = e.stat(follow_symlinks=False)
                except OSError:
                    continue
                out[e.name] = (st.st_size, st.st_mtime_ns, st.st_ino, stat.S_IFMT(st.st_mode))
    except OSError:
        pass
    return out


def _package_snapshot() -> dict:
    """``{path: (size, mode, SHA-256)}`` of every file of the installed
    avblocks package (the grader's own code; a time stamp alone may change,
    which Landlock does not prevent and which changes nothing; a mode alone
    is the submission's fault, not a reason to stop grading the class: see
    :func:`_grade_one`)."""
    import hashlib
    root = Path(__file__).resolve().parents[1]
    out = {}
    for dirpath, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if d not in ("__pycache__", "node_modules")]
        for f in files:
            p = os.path.join(dirpath, f)
            try:
                st = os.stat(p, follow_symlinks=False)
                with open(p, "rb") as fh:
                    digest = hashlib.sha256(fh.read()).hexdigest()
            except OSError:
                continue
            out[p] = (st.st_size, st.st_mode, digest)
    return out


class GraderTampered(Exception):
    """The grader's own files changed while it graded: its results cannot
    be trusted (exit status 2)."""


def grade_all(lab, paths, *, seeds=None, **kw) -> list[Report]:
    """Grade several files of one folder. Every file is read before any
    student's code runs (each is graded from that copy, whatever a
    submission writes later); after each submission the folder and the
    grader's own package are compared with their state before it, and a
    submission that changed them fails (``files``), or stops the run when
    the grader's files changed (:class:`GraderTampered`).

    ``seeds``: one seed (or None) per path."""
    from . import oscalls
    paths = [Path(p) for p in paths]
    seeds = list(seeds) if seeds is not None else [None] * len(paths)
    texts = [read_submission(p) for p in paths]
    folders = sorted({p.parent for p in paths})
    before = {f: _snapshot(f) for f in folders}
    pkg = _package_snapshot()
    reports = []
    n_checks = len(lab.all_checks()) + len(kw.get("extra", ()))
    limits = kw.pop("limits", None) or limits_for(kw.get("timeout") or DEFAULT_TIMEOUT,
                                                  kw.get("memory_mb", DEFAULT_MEMORY_MB),
                                                  n_checks)
    # the next student's process starts while this one is graded, only where
    # no student's process can reach another (Landlock ABI 6+, a subreaper)
    ahead = oscalls.full_isolation()
    nxt = None
    with contextlib.ExitStack() as stack:
        stack.enter_context(oscalls.undumpable())
        stack.callback(lambda: nxt is not None and nxt.close())
        for i, (p, (text, err), seed) in enumerate(zip(paths, texts, seeds)):
            sandbox, nxt = nxt, None
            if ahead and i + 1 < len(paths) and texts[i + 1][1] is None:
                nxt = Sandbox(limits).start()
            reports.append(_grade_one(lab, p, text, err, seed, sandbox, limits, folders,
                                      before, pkg, kw))
    return reports


def _grade_one(lab, p, text, err, seed, sandbox, limits, folders, before, pkg, kw):
    """One file of :func:`grade_all`, and the check of what it changed."""
    if err:
        if sandbox is not None:
            sandbox.close()
        r = Report(lab=lab.number, file=str(p), seed=seed)
        r.checks.append(CheckResult("load", False, _one_line(err), 0.0))
        for c in lab.all_checks() + [as_check(c) for c in kw.get("extra", ())]:
            r.checks.append(CheckResult(c.name, False, "not run: the file did not load",
                                        c.points, c.visibility))
        return r
    r = run_checks(lab, p, seed=seed, source=text, limits=limits, sandbox=sandbox, **kw)
    changed = []
    for f in folders:
        now = _snapshot(f)
        changed += sorted(n for n in set(now) | set(before[f])
                          if now.get(n) != before[f].get(n))
        before[f] = now
    if changed:
        for c in r.checks:
            if c.passed:
                c.passed = False
                c.message = "void: " + c.message
        r.checks.append(CheckResult("files", False, (
            f"the folder changed while this submission ran ({', '.join(changed[:5])}"
            f"{' ...' if len(changed) > 5 else ''}): a submission must not write files; "
            f"every other file was graded from the copy read before any code ran"), 0.0))
    now = _package_snapshot()
    if now != pkg:
        content = {k: (v[0], v[2]) for k, v in now.items()}
        if content != {k: (v[0], v[2]) for k, v in pkg.items()}:
            raise GraderTampered(
                f"the grader's own files (the avblocks package) changed while {p.name} ran; "
                f"reinstall avblocks and grade in a read-only installation")
        # only modes changed (chmod, which Landlock does not stop): the code the
        # grader runs is the same, every module it needs is loaded; the
        # submission fails, the modes are put back, the class goes on
        moved = sorted(k for k in now if now[k][1] != pkg[k][1])
        for k in moved:
            with contextlib.suppress(OSError):
                os.chmod(k, stat.S_IMODE(pkg[k][1]))
        for c in r.checks:
            if c.passed:
                c.passed = False
                c.message = "void: " + c.message
        names = ", ".join(os.path.relpath(k, Path(__file__).resolve().parents[1])
                          for k in moved[:3])
        r.checks.append(CheckResult("files", False, _one_line(
            f"it changed the mode of the grader's own files ({names}"
            f"{' ...' if len(moved) > 3 else ''}): a submission must not touch them; "
            f"their modes were put back"), 0.0))
        pkg.clear()
        pkg.update(_package_snapshot())
    return r


__all__ = ["Check", "CheckResult", "DEFAULT_MEMORY_MB", "DEFAULT_TIMEOUT", "Failed",
           "MAX_TIMEOUT",
           "GraderTampered", "Lab", "Report", "as_check", "check_ports", "compare",
           "describe", "expect_shape", "fmt", "grade_all", "read_submission", "run_checks",
           "run_checks_here", "seed_for"]
