"""Every platform call of the grader's sandbox, with its fallbacks.

The grader runs a student's code in a child process (see
:mod:`avblocks.labs.sandbox`). What the operating system offers to contain
that process differs between Linux, macOS and Windows; this module is the
only place that knows, so that the rest of the grader asks for a feature
and is told, in words, what it got:

* **its own session** (POSIX ``setsid``, through ``start_new_session``;
  Windows ``CREATE_NEW_PROCESS_GROUP``): the terminal's Ctrl-C does not
  reach it, and it can be killed with its group;
* **resource limits** (``setrlimit``: ``RLIMIT_AS`` memory, ``RLIMIT_CPU``,
  ``RLIMIT_NPROC`` processes, ``RLIMIT_NOFILE``, ``RLIMIT_FSIZE``,
  ``RLIMIT_CORE``) on Linux and macOS (macOS may refuse or not enforce
  ``RLIMIT_AS``; ``RLIMIT_NPROC`` does not bind root); none on Windows;
  the report says which were set;
* **Landlock** (Linux 5.13+): no file written outside its own folder; from
  ABI 4 no TCP, from ABI 6 no signal to any process outside (the grader,
  other students); ``ptrace`` of outside processes always refused.
  Elsewhere nothing stops a write, and the grader detects changed files
  afterwards (:func:`avblocks.labs.grading.grade_all`);
* **no socket, no change of a file's mode, owner or times, no ptrace**
  (Linux x86-64 and arm64, seccomp): UDP, Unix sockets (a Docker or
  ssh-agent socket), ``chmod``/``chown``/``utime``/``setxattr`` and
  ``io_uring`` are refused with ``EPERM``, which Landlock does not cover;
* **no capability** (Linux): a student's process started by a grader
  running as root drops every capability (it cannot raise a hard limit,
  read another process's environment, or regain them by ``execve``);
* **a grader the student cannot inspect** (Linux): while it grades, the
  grader is not dumpable, so a process of the same user cannot read its
  ``/proc/<pid>/environ`` (the instructor's tokens and keys);
* **killing everything it started**: a supervisor that is the "child
  subreaper" of the student's process (Linux ``prctl``), so that even a
  daemon that double-forked out of the session comes back to it and is
  killed; elsewhere ``killpg`` and the process tree (``/proc``, ``psutil``,
  ``ps`` or ``taskkill``), which a daemon can escape.

Tests force each fallback with :func:`disabled` (the names in
:data:`FEATURES`); the child and the supervisor are told which features
are off, so the whole chain takes the fallback path.

This module imports only the standard library: the supervisor runs it as a
script (``python -I -S oscalls.py supervise ...``), before and without
NumPy or avblocks.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time

#: the features :func:`disabled` can switch off (to test the fallbacks)
FEATURES = ("resource", "landlock", "killpg", "setsid", "subreaper", "proc", "psutil",
            "select", "supervisor", "seccomp", "capabilities", "dumpable")

_OFF: set = set(filter(None, os.environ.get("AVBLOCKS_LAB_DISABLE", "").split(",")))

IS_WINDOWS = os.name == "nt"
IS_LINUX = sys.platform.startswith("linux")


def enabled(name) -> bool:
    """True unless feature ``name`` was switched off (:func:`disabled`)."""
    return name not in _OFF


def off() -> list:
    """The features switched off in this process (passed on to the child)."""
    return sorted(_OFF)


def set_off(names):
    """Switch off exactly ``names`` in this process (the child and the
    supervisor call it with what the grader sends them)."""
    bad = set(names) - set(FEATURES)
    if bad:
        raise ValueError(f"unknown sandbox feature(s) {sorted(bad)}; known: {FEATURES}")
    _OFF.clear()
    _OFF.update(names)


@contextlib.contextmanager
def disabled(*names):
    """Run the grader with these features off, as on a platform without them
    (a test helper: ``with disabled("landlock", "resource"): run_checks(...)``)."""
    old = set(_OFF)
    set_off(old | set(names))
    try:
        yield
    finally:
        set_off(old)


def _resource():
    if not enabled("resource"):
        return None
    try:
        import resource
    except ImportError:            # Windows
        return None
    return resource


# ------------------------------------------------------------------ starting
def popen_options() -> dict:
    """Keyword arguments of :class:`subprocess.Popen` that put the child in
    a session (POSIX) or process group (Windows) of its own, so that a
    signal for the grader's terminal (Ctrl-C) does not reach it and the
    grader can end it with everything it started."""
    if IS_WINDOWS:
        return {"creationflags": subprocess.CREATE_NEW_PROCESS_GROUP
                | getattr(subprocess, "CREATE_NO_WINDOW", 0)}
    if enabled("setsid"):
        return {"start_new_session": True}
    return {}


def child_environment(workdir) -> dict:
    """The whole environment of the student's process: nothing of the
    grader's (no tokens, no ``PYTHONPATH``), one thread per math library
    (fair time limits, no thread storms against ``RLIMIT_NPROC``), its
    own home and temporary folder, a plotting backend without a display."""
    env = {"HOME": str(workdir), "TMPDIR": str(workdir), "TEMP": str(workdir),
           "TMP": str(workdir), "LANG": "C.UTF-8", "LC_ALL": "C.UTF-8",
           "PATH": os.defpath, "MPLBACKEND": "Agg", "MPLCONFIGDIR": str(workdir),
           "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
           "NUMEXPR_NUM_THREADS": "1", "VECLIB_MAXIMUM_THREADS": "1",
           "PYTHONHASHSEED": "0", "PYTHONIOENCODING": "utf-8"}
    if IS_WINDOWS:                 # Python and its DLLs need these to start
        for key in ("SYSTEMROOT", "SYSTEMDRIVE", "WINDIR", "COMSPEC", "PATHEXT"):
            if key in os.environ:
                env[key] = os.environ[key]
    return env


# ------------------------------------------------------------------ limits
def apply_limits(*, memory_mb=None, cpu_s=None, processes=None, files=None,
                 file_mb=None) -> dict:
    """Set this process's resource limits (the child calls it before it
    runs the student's code). Returns ``{limit: what was done}`` in words,
    for the report: a limit the platform does not have is said, not an
    error."""
    res = _resource()
    out = {}
    if res is None:
        why = ("not set: this platform has no setrlimit (Windows)" if enabled("resource")
               else "not set: setrlimit switched off")
        for key, val in (("memory", memory_mb), ("cpu", cpu_s), ("processes", processes),
                         ("open_files", files), ("file_size", file_mb)):
            if val:
                out[key] = why
        return out

    def setlim(key, name, value, text):
        rl = getattr(res, name, None)
        if rl is None:
            out[key] = f"not set: this platform has no {name}"
            return
        try:
            _, hard = res.getrlimit(rl)
            value = min(int(value), 2 ** 62)
            if hard != res.RLIM_INFINITY:
                value = min(value, hard)
            # the hard limit comes down to the soft one: a process may always
            # raise its soft limit up to its hard limit, and a student's would
            new_hard = value
            if key == "cpu":               # SIGXCPU at the soft limit, SIGKILL 5 s later
                new_hard = value + 5 if hard == res.RLIM_INFINITY else min(hard, value + 5)
            res.setrlimit(rl, (value, new_hard))
            out[key] = f"{text(value)} ({name})"
        except (ValueError, OSError, OverflowError) as e:
            out[key] = f"not set: {name} refused ({e})"

    if memory_mb:
        setlim("memory", "RLIMIT_AS", memory_mb * 2 ** 20,
               lambda v: f"{v // 2 ** 20} MiB of address space")

    if cpu_s:
        # at most 10**9 s: the kernel counts CPU time in nanoseconds, and a larger
        # limit wrapped around to an immediate SIGXCPU
        setlim("cpu", "RLIMIT_CPU", max(1, int(min(float(cpu_s), 1e9))),
               lambda v: f"{v} s of CPU time")
    if processes:
        if os.geteuid() == 0:
            out["processes"] = "not enforced: the grader runs as root (uid 0), which " \
                               "RLIMIT_NPROC does not bind"
        elif IS_LINUX and enabled("proc"):
            mine = _user_tasks(os.geteuid())
            setlim("processes", "RLIMIT_NPROC", mine + int(processes),
                   lambda v: f"{int(processes)} more processes or threads than the user's "
                             f"{mine}")
        else:
            out["processes"] = "not set: the user's process count is unknown here"
    if files:
        setlim("open_files", "RLIMIT_NOFILE", files, lambda v: f"{v} open files")
    if file_mb:
        setlim("file_size", "RLIMIT_FSIZE", file_mb * 2 ** 20,
               lambda v: f"files up to {v // 2 ** 20} MiB")
    setlim("core", "RLIMIT_CORE", 0, lambda v: "no core dumps")
    return out


def _user_tasks(uid) -> int:
    """Threads of every process of ``uid`` (what ``RLIMIT_NPROC`` counts on
    Linux), from ``/proc``."""
    n = 0
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/status", "rb") as f:
                txt = f.read().decode("ascii", "replace")
        except OSError:
            continue
        fields = dict(line.split(":", 1) for line in txt.splitlines() if ":" in line)
        try:
            if int(fields["Uid"].split()[0]) == uid:
                n += int(fields["Threads"])
        except (KeyError, ValueError, IndexError):
            pass
    return n


# ------------------------------------------------------------------ Landlock
_LL_FS_ABI1 = sum(1 << b for b in (1, 4, 5, 6, 7, 8, 9, 10, 11, 12))   # the write rights
_LL_REFER, _LL_TRUNCATE, _LL_IOCTL_DEV = 1 << 13, 1 << 14, 1 << 15
_LL_FILE_WRITE = (1 << 1)                                           # WRITE_FILE
_LL_EXECUTE, _LL_READ_FILE, _LL_READ_DIR = 1 << 0, 1 << 2, 1 << 3      # the read rights
_LL_READ = _LL_EXECUTE | _LL_READ_FILE | _LL_READ_DIR

#: system folders a student's process may read (and run programs from): the
#: C library, the dynamic loader, locales and zone data live there; the
#: Python installation and the library are added by :func:`readable_roots`
_SYSTEM_READ = ("/usr", "/lib", "/lib64", "/lib32", "/libx32", "/bin", "/sbin", "/proc",
                "/sys", "/nix/store")
#: single files outside those (the loader's cache, the time zone, the
#: random devices); not the rest of /etc (``/etc/shadow`` is root's to read)
_FILES_READ = ("/etc/ld.so.cache", "/etc/localtime", "/dev/urandom", "/dev/random",
               "/dev/zero", "/dev/full")


def readable_roots() -> list:
    """The folders a student's process may read under Landlock: the Python
    installation (prefixes, the interpreter's folder, every folder on
    ``sys.path``: the standard library, site-packages, avblocks itself) and
    the system folders of :data:`_SYSTEM_READ`. Not the user's home, not
    /tmp, not the class folder, not an instructor's extra checks, not the
    tests and their reference solutions."""
    import sysconfig
    out = []
    cands = [sys.prefix, sys.exec_prefix, sys.base_prefix, sys.base_exec_prefix,
             os.path.dirname(os.path.realpath(sys.executable)),
             *(sysconfig.get_paths().get(k, "") for k in ("stdlib", "platstdlib", "purelib",
                                                          "platlib")),
             *sys.path, *_SYSTEM_READ]
    for p in cands:
        if not p or not os.path.isabs(p):
            continue
        real = os.path.realpath(p)
        if os.path.isdir(real) and real not in out:
            out.append(real)
    return out


def landlock_abi() -> int:
    """The kernel's Landlock ABI version (0: none, or switched off)."""
    if not (IS_LINUX and enabled("landlock")):
        return 0
    try:
        import ctypes
        libc = ctypes.CDLL(None, use_errno=True)
        abi = libc.syscall(444, None, ctypes.c_size_t(0), ctypes.c_uint32(1))
    except (OSError, AttributeError):
        return 0
    return max(0, int(abi))


def restrict_writes(workdir, readable=None) -> dict:
    """Landlock this process (and all it starts): files may be created,
    written, truncated or removed only under ``workdir`` (and ``/dev/null``
    written); files may be read, and programs run, only under ``workdir``
    and the folders of ``readable`` (default :func:`readable_roots`: the
    Python installation, avblocks, system folders), so that a student's
    code cannot read the class folder, an instructor's hidden checks, the
    reference solutions or the user's files; with ABI 4+ no TCP
    ``bind``/``connect``; with ABI 6+ no signal to, and no abstract-socket
    connection with, any process outside (the grader, the supervisor, other
    students). Landlock also refuses ``ptrace`` of outside processes.
    Returns ``{"files": ..., "reads": ..., "network": ..., "signals": ...}``
    in words."""
    abi = landlock_abi()
    if abi <= 0:
        why = ("not restricted: Landlock is not available (Linux 5.13+ only)"
               if enabled("landlock") else "not restricted: Landlock switched off")
        return {"files": why, "reads": why, "network": why, "signals": why}
    import ctypes
    libc = ctypes.CDLL(None, use_errno=True)
    readable = readable_roots() if readable is None else [str(p) for p in readable]
    fs = _LL_FS_ABI1 | (_LL_REFER if abi >= 2 else 0) | (_LL_TRUNCATE if abi >= 3 else 0) \
        | (_LL_IOCTL_DEV if abi >= 5 else 0) | _LL_READ
    net = 3 if abi >= 4 else 0
    scoped = 3 if abi >= 6 else 0

    class Attr(ctypes.Structure):
        _fields_ = [("fs", ctypes.c_uint64), ("net", ctypes.c_uint64),
                    ("scoped", ctypes.c_uint64)]

    class Rule(ctypes.Structure):
        _pack_ = 1
        _fields_ = [("allowed", ctypes.c_uint64), ("parent_fd", ctypes.c_int32)]

    size = 24 if abi >= 6 else 16 if abi >= 4 else 8
    attr = Attr(fs, net, scoped)
    rs = libc.syscall(444, ctypes.byref(attr), ctypes.c_size_t(size), ctypes.c_uint32(0))
    if rs < 0:
        err = os.strerror(ctypes.get_errno())
        why = f"not restricted: Landlock refused the ruleset ({err})"
        return {"files": why, "reads": why, "network": why, "signals": why}
    try:
        rules = [(str(workdir), fs)]
        file_rights = _LL_READ_FILE | _LL_EXECUTE
        if os.path.exists(os.devnull):
            rules.append((os.devnull, fs & (_LL_FILE_WRITE | _LL_TRUNCATE | _LL_IOCTL_DEV
                                            | _LL_READ_FILE)))
        rules += [(p, _LL_READ) for p in readable if os.path.isdir(p)]
        rules += [(p, file_rights) for p in _FILES_READ
                  if os.path.exists(p) and not os.path.isdir(p)]
        for path, allowed in rules:
            try:
                fd = os.open(path, getattr(os, "O_PATH", os.O_RDONLY) | os.O_CLOEXEC)
            except OSError:
                if path == str(workdir):
                    raise
                continue                                 # gone since it was listed
            if not os.path.isdir(path):                  # a file takes file rights only
                allowed &= file_rights | _LL_FILE_WRITE | _LL_TRUNCATE | _LL_IOCTL_DEV
            try:
                rule = Rule(allowed, fd)
                if libc.syscall(445, ctypes.c_int(rs), ctypes.c_int(1), ctypes.byref(rule),
                                ctypes.c_uint32(0)) < 0:
                    raise OSError(ctypes.get_errno(), f"landlock_add_rule({path})")
            finally:
                os.close(fd)
        if libc.prctl(38, 1, 0, 0, 0) < 0:                       # PR_SET_NO_NEW_PRIVS
            raise OSError(ctypes.get_errno(), "prctl(PR_SET_NO_NEW_PRIVS)")
        if libc.syscall(446, ctypes.c_int(rs), ctypes.c_uint32(0)) < 0:
            raise OSError(ctypes.get_errno(), "landlock_restrict_self")
    except OSError as e:
        why = f"not restricted: Landlock failed ({e})"
        return {"files": why, "reads": why, "network": why, "signals": why}
    finally:
        os.close(rs)
    return {"files": f"writes only inside its own temporary folder (Landlock ABI {abi})",
            "reads": "reads only its own folder, the Python installation, avblocks and "
                     "system folders: not the class folder, the user's files, extra "
                     "checks or the tests (Landlock)",
            "network": ("no TCP bind or connect (Landlock)" if net else
                        "not restricted: Landlock ABI < 4 has no network rules"),
            "signals": ("no signal to, and no ptrace of, any process outside its own "
                        "(Landlock)" if scoped else
                        "ptrace of outside processes refused (Landlock); signals not "
                        "restricted: Landlock ABI < 6")}


# ------------------------------------------------------------------ seccomp
#: ``AUDIT_ARCH_*`` of the architectures whose system call numbers are known here
_AUDIT_ARCH = {"x86_64": 0xC000003E, "amd64": 0xC000003E, "aarch64": 0xC00000B7,
               "arm64": 0xC00000B7}

#: the calls a student's process may not make, by architecture (Linux's
#: ``arch/x86/entry/syscalls/syscall_64.tbl`` and ``include/uapi/asm-generic/unistd.h``):
#: sockets (UDP, Unix: Landlock covers TCP only), a file's mode, owner, times
#: and extended attributes (Landlock covers writes, not these), ptrace and
#: another process's memory, io_uring (which makes the others without a call)
_DENIED_CALLS = {
    "x86_64": {"socket": 41, "chmod": 90, "fchmod": 91, "chown": 92, "fchown": 93,
               "lchown": 94, "ptrace": 101, "utime": 132, "setxattr": 188,
               "lsetxattr": 189, "fsetxattr": 190, "removexattr": 197, "lremovexattr": 198,
               "fremovexattr": 199, "utimes": 235, "fchownat": 260, "futimesat": 261,
               "fchmodat": 268, "utimensat": 280, "process_vm_readv": 310,
               "process_vm_writev": 311, "io_uring_setup": 425, "io_uring_enter": 426,
               "io_uring_register": 427, "fchmodat2": 452, "setxattrat": 463,
               "removexattrat": 466},
    "aarch64": {"setxattr": 5, "lsetxattr": 6, "fsetxattr": 7, "removexattr": 14,
                "lremovexattr": 15, "fremovexattr": 16, "fchmod": 52, "fchmodat": 53,
                "fchownat": 54, "fchown": 55, "utimensat": 88, "ptrace": 117, "socket": 198,
                "process_vm_readv": 270, "process_vm_writev": 271, "io_uring_setup": 425,
                "io_uring_enter": 426, "io_uring_register": 427, "fchmodat2": 452,
                "setxattrat": 463, "removexattrat": 466},
}


def seccomp_arch() -> str | None:
    """``"x86_64"`` or ``"aarch64"`` where :func:`restrict_syscalls` can
    filter this process's system calls (64-bit Linux on those), else None."""
    if not (IS_LINUX and enabled("seccomp")):
        return None
    import platform
    import struct
    arch = {"amd64": "x86_64", "arm64": "aarch64"}.get(platform.machine().lower(),
                                                     platform.machine().lower())
    return arch if arch in _DENIED_CALLS and struct.calcsize("P") == 8 else None


#: the calls that send a signal to a process named by their first argument
#: (kill, tgkill, rt_sigqueueinfo, rt_tgsigqueueinfo): refused for the
#: protected processes of :func:`restrict_syscalls`
_SIGNAL_CALLS = {"x86_64": (62, 234, 129, 297), "aarch64": (129, 131, 138, 240)}
#: refused outright: tkill (a thread of any process), pidfd_send_signal, pidfd_getfd
_DENIED_CALLS["x86_64"].update(tkill=200, pidfd_send_signal=424, pidfd_getfd=438)
_DENIED_CALLS["aarch64"].update(tkill=130, pidfd_send_signal=424, pidfd_getfd=438)


def _seccomp_program(arch, protect=()) -> list:
    """The BPF program: a call of another architecture (a 32-bit call from
    a 64-bit process, x32) or in :data:`_DENIED_CALLS` gets ``EPERM``; so
    does a signal (:data:`_SIGNAL_CALLS`) whose target, the low 32 bits of
    the first argument, is one of ``protect`` (process ids, ``-pgid`` for a
    group, ``-1`` for every process); everything else is allowed."""
    import errno
    ld_abs, jeq, jge, ret = 0x20, 0x15, 0x35, 0x06
    allow, deny = 0x7FFF0000, 0x00050000 | errno.EPERM
    # (code, jump-if-true label, jump-if-false label, k); labels resolved below
    prog = [(ld_abs, None, None, 4),                     # seccomp_data.arch
            (jeq, None, "deny", _AUDIT_ARCH[arch]),
            (ld_abs, None, None, 0)]                     # seccomp_data.nr
    if arch == "x86_64":
        prog.append((jge, "deny", None, 0x40000000))     # the x32 ABI
    prog += [(jeq, "deny", None, nr) for nr in sorted(_DENIED_CALLS[arch].values())]
    targets = sorted({int(p) & 0xFFFFFFFF for p in protect})
    if targets:
        prog += [(jeq, "signal", None, nr) for nr in _SIGNAL_CALLS[arch]]
    prog.append((ret, None, None, allow))
    if targets:
        prog.append(("label", "signal", None, None))
        prog.append((ld_abs, None, None, 16))            # args[0], its low 32 bits
        prog += [(jeq, "deny", None, t) for t in targets]
        prog.append((ret, None, None, allow))
    prog += [("label", "deny", None, None), (ret, None, None, deny)]
    at, out = {}, []
    for ins in prog:
        if ins[0] == "label":
            at[ins[1]] = len(out)
        else:
            out.append(ins)

    def off(label, i):
        if label is None:
            return 0
        d = at[label] - i - 1
        if not 0 <= d < 256:
            raise ValueError("a seccomp jump out of range")
        return d

    return [(c, off(t, i), off(f, i), k) for i, (c, t, f, k) in enumerate(out)]


def restrict_syscalls(protect=()) -> dict:
    """Install the seccomp filter of :func:`_seccomp_program` in this
    process (and all it starts; it cannot be removed): no socket of any
    kind, no ``chmod``/``chown``/``utime``/``setxattr``, no ``ptrace`` or
    ``process_vm_*``, no ``io_uring``, and no signal to the processes of
    ``protect`` (the grader and the supervisor, by process and group id,
    and ``-1``: where Landlock cannot scope signals, before Linux 6.12, a
    student's process killed its supervisor, then left a daemon running).
    Sets ``PR_SET_NO_NEW_PRIVS`` first. Returns ``{"sockets": ...,
    "file_modes": ..., "grader_signals": ...}`` in words (``grader_signals``
    only when ``protect`` is given)."""
    arch = seccomp_arch()
    if arch is None:
        why = ("not restricted: seccomp switched off" if not enabled("seccomp") else
               "not restricted: no seccomp filter for this platform (Linux x86-64 and "
               "arm64 only)")
        return {"sockets": why, "file_modes": why}
    import ctypes
    prog = _seccomp_program(arch, protect)

    class Insn(ctypes.Structure):
        _fields_ = [("code", ctypes.c_uint16), ("jt", ctypes.c_uint8), ("jf", ctypes.c_uint8),
                    ("k", ctypes.c_uint32)]

    class Prog(ctypes.Structure):
        _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.POINTER(Insn))]

    insns = (Insn * len(prog))(*[Insn(*i) for i in prog])
    fprog = Prog(len(prog), ctypes.cast(insns, ctypes.POINTER(Insn)))
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(38, 1, 0, 0, 0) < 0:                       # PR_SET_NO_NEW_PRIVS
            raise OSError(ctypes.get_errno(), "prctl(PR_SET_NO_NEW_PRIVS)")
        if libc.prctl(22, 2, ctypes.byref(fprog), 0, 0) < 0:     # PR_SET_SECCOMP, FILTER
            raise OSError(ctypes.get_errno(), "prctl(PR_SET_SECCOMP)")
    except (OSError, AttributeError) as e:
        why = f"not restricted: seccomp refused the filter ({e})"
        return {"sockets": why, "file_modes": why}
    out = {"sockets": "no socket of any kind: no UDP, no Unix socket (seccomp)",
           "file_modes": "no chmod, chown, utime or extended attributes, no ptrace "
                         "(seccomp)"}
    if protect:
        out["grader_signals"] = "no signal to the grader, its supervisor or their group " \
                                "(seccomp)"
    return out


# ------------------------------------------------------------------ capabilities
def drop_capabilities() -> str:
    """Give up every capability of this process for good (Linux): the
    bounding and ambient sets emptied, the "root" secure bits locked, then
    the effective, permitted and inheritable sets cleared; with
    ``PR_SET_NO_NEW_PRIVS`` no ``execve`` gives any back. A process of a
    grader run as root then cannot raise a hard limit, read the grader's
    memory or environment, change another user's files or bypass their
    permissions. Returns what was done, in words."""
    if not (IS_LINUX and enabled("capabilities")):
        return ("not dropped: capabilities switched off" if IS_LINUX else
                "none to drop on this platform")
    import ctypes
    try:
        libc = ctypes.CDLL(None, use_errno=True)
    except OSError as e:
        return f"not dropped: no C library ({e})"
    try:
        with open("/proc/sys/kernel/cap_last_cap") as f:
            last = int(f.read())
    except (OSError, ValueError):
        last = 63
    had = _effective_caps()
    libc.prctl(38, 1, 0, 0, 0)                                   # PR_SET_NO_NEW_PRIVS
    for cap in range(last + 1):
        libc.prctl(24, cap, 0, 0, 0)                             # PR_CAPBSET_DROP
    libc.prctl(47, 4, 0, 0, 0)                                   # PR_CAP_AMBIENT_CLEAR_ALL
    if os.geteuid() == 0:
        # SECBIT_NOROOT, NO_SETUID_FIXUP, KEEP_CAPS_LOCKED, NO_CAP_AMBIENT_RAISE, locked
        libc.prctl(28, 0xEF, 0, 0, 0)                            # PR_SET_SECUREBITS

    class Header(ctypes.Structure):
        _fields_ = [("version", ctypes.c_uint32), ("pid", ctypes.c_int)]

    class Data(ctypes.Structure):
        _fields_ = [("effective", ctypes.c_uint32), ("permitted", ctypes.c_uint32),
                    ("inheritable", ctypes.c_uint32)]

    head, data = Header(0x20080522, 0), (Data * 2)()            # _LINUX_CAPABILITY_VERSION_3
    if libc.capset(ctypes.byref(head), data) < 0:
        return f"not dropped: capset refused ({os.strerror(ctypes.get_errno())})"
    left = _effective_caps()
    if left:
        return f"not dropped: capabilities {left:#x} are left"
    return ("every capability dropped (the grader runs as root)" if had else
            "none (the grader does not run as root)")


def _effective_caps() -> int:
    """This process's effective capabilities (``CapEff`` of /proc/self/status), 0 if unknown."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("CapEff:"):
                    return int(line.split()[1], 16)
    except (OSError, ValueError, IndexError):
        pass
    return 0


# ------------------------------------------------------------------ the grader itself
_UNDUMPABLE = [0, None]                  # depth of undumpable(), the state to restore


@contextlib.contextmanager
def undumpable():
    """While grading, make this process (the grader) not dumpable (Linux
    ``PR_SET_DUMPABLE``): another process of the same user, a student's
    among them, can no longer open its ``/proc/<pid>/environ``, ``mem`` or
    ``fd`` (a process without ``CAP_SYS_PTRACE``, as the student's is).
    The previous state comes back on the way out; nesting is counted."""
    if not (IS_LINUX and enabled("dumpable")):
        yield
        return
    import ctypes
    try:
        libc = ctypes.CDLL(None, use_errno=True)
    except OSError:
        yield
        return
    if _UNDUMPABLE[0] == 0:
        _UNDUMPABLE[1] = libc.prctl(3, 0, 0, 0, 0)                # PR_GET_DUMPABLE
        libc.prctl(4, 0, 0, 0, 0)                                # PR_SET_DUMPABLE 0
    _UNDUMPABLE[0] += 1
    try:
        yield
    finally:
        _UNDUMPABLE[0] -= 1
        if _UNDUMPABLE[0] == 0 and _UNDUMPABLE[1] in (1, 2):
            libc.prctl(4, 1, 0, 0, 0)


# ------------------------------------------------------------------ processes
def become_subreaper() -> bool:
    """Make this process the "child subreaper" of everything it starts
    (Linux): an orphaned descendant (a daemon that double-forked away from
    its session) is re-parented here instead of to ``init``, so it can
    still be found and killed. False where there is no such thing."""
    if not (IS_LINUX and enabled("subreaper")):
        return False
    try:
        import ctypes
        return ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _parents() -> dict:
    """``{pid: parent pid}`` of every process this user can see."""
    if IS_LINUX and enabled("proc"):
        out = {}
        for d in os.listdir("/proc"):
            if not d.isdigit():
                continue
            try:
                with open(f"/proc/{d}/stat", "rb") as f:
                    stat = f.read().decode("ascii", "replace")
                out[int(d)] = int(stat.rsplit(")", 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue
        return out
    if enabled("psutil"):
        with contextlib.suppress(ImportError):
            import psutil
            return {p.pid: p.info["ppid"] for p in psutil.process_iter(["ppid"])}
    if IS_WINDOWS:
        return {}
    try:
        text = subprocess.run(["ps", "-A", "-o", "pid=,ppid="], capture_output=True,
                              text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        return {}
    out = {}
    for line in text.splitlines():
        with contextlib.suppress(ValueError):
            pid, ppid = map(int, line.split())
            out[pid] = ppid
    return out


def descendants(pid) -> list:
    """Every live descendant of ``pid`` (children, grandchildren...)."""
    parents = _parents()
    kids: dict = {}
    for p, pp in parents.items():
        kids.setdefault(pp, []).append(p)
    out, stack = [], list(kids.get(pid, ()))
    while stack:
        p = stack.pop()
        if p in out or p == pid:
            continue
        out.append(p)
        stack.extend(kids.get(p, ()))
    return out


def _kill(pid, group=False):
    if IS_WINDOWS:
        with contextlib.suppress(OSError, subprocess.SubprocessError):
            subprocess.run(["taskkill", "/F", "/T", "/PID", str(pid)], capture_output=True,
                           timeout=30)
        return
    if group and enabled("killpg") and hasattr(os, "killpg"):
        with contextlib.suppress(OSError):
            os.killpg(pid, signal.SIGKILL)
    with contextlib.suppress(OSError):
        os.kill(pid, signal.SIGKILL)


def kill_tree(pid, *, mine=False, rounds=50):
    """Kill process ``pid``, its session or process group and every
    descendant found, again until none is left (a process that forks while
    the kill goes on is caught by a later round). ``mine``: also every
    descendant of this process (the supervisor, a subreaper, collects the
    orphans of ``pid``'s tree that way, and reaps what it killed; the
    grader never reaps, its other children's statuses are theirs)."""
    if not IS_WINDOWS and enabled("killpg") and hasattr(os, "killpg"):
        with contextlib.suppress(OSError):
            os.killpg(pid, signal.SIGSTOP)       # freeze the group: no fork while we look
    for _ in range(rounds):
        rest = descendants(pid)
        if mine:
            rest += [p for p in descendants(os.getpid()) if p not in rest]
        _kill(pid, group=True)
        if not rest:
            if mine:
                reap()
            return
        for p in rest:
            _kill(p, group=True)
        if mine:
            reap()
        time.sleep(0.005)


def reap():
    """Collect every dead child of this process (POSIX), so none stays a
    zombie."""
    if IS_WINDOWS:
        return
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        except OSError:
            return
        if pid == 0:
            return


def remove_tree(path) -> bool:
    """Remove the folder ``path`` and everything in it, however deep and
    whatever its modes: the student's own folder, in which its code may
    have nested thousands of folders (``shutil.rmtree`` recursed until a
    RecursionError ended the grader) or made folders it cannot list
    (``mkdir(name, 0)``). Every folder met is moved up beside ``path``'s
    top, so depth never matters and two descriptors suffice. Never follows
    a symbolic link. True when it is gone."""
    import shutil
    import stat as st_
    if IS_WINDOWS or not (os.open in os.supports_dir_fd and os.rename in os.supports_dir_fd):
        with contextlib.suppress(OSError, RecursionError):
            shutil.rmtree(path, ignore_errors=True)
        return not os.path.lexists(path)
    try:
        top = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except FileNotFoundError:
        return True
    except OSError:
        with contextlib.suppress(OSError):
            os.unlink(path)                          # a link or a file in its place
        return not os.path.lexists(path)
    try:
        todo, n = [], 0
        with contextlib.suppress(OSError):
            os.chmod(top, 0o700)
        with contextlib.suppress(OSError):
            todo = [e.name for e in os.scandir(top)]
        while todo:
            name = todo.pop()
            try:
                mode = os.stat(name, dir_fd=top, follow_symlinks=False).st_mode
            except OSError:
                continue
            if not st_.S_ISDIR(mode):
                with contextlib.suppress(OSError):
                    os.unlink(name, dir_fd=top)
                continue
            with contextlib.suppress(OSError):
                os.chmod(name, 0o700, dir_fd=top)    # a folder made unreadable
            try:
                sub = os.open(name, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC,
                              dir_fd=top)
            except OSError:
                continue
            try:
                for e in list(os.scandir(sub)):
                    try:
                        is_dir = e.is_dir(follow_symlinks=False)
                    except OSError:
                        is_dir = False
                    if is_dir:                       # moved up: depth does not matter
                        n += 1
                        flat = f".avblocks-flat-{n}"
                        with contextlib.suppress(OSError):    # moving needs its write right
                            os.chmod(e.name, 0o700, dir_fd=sub)
                        with contextlib.suppress(OSError):
                            os.rename(e.name, flat, src_dir_fd=sub, dst_dir_fd=top)
                            todo.append(flat)
                    else:
                        with contextlib.suppress(OSError):
                            os.unlink(e.name, dir_fd=sub)
            except OSError:
                pass
            finally:
                os.close(sub)
            with contextlib.suppress(OSError):
                os.rmdir(name, dir_fd=top)
    finally:
        os.close(top)
    with contextlib.suppress(OSError):
        os.rmdir(path)
    return not os.path.lexists(path)


def status_text(returncode) -> str:
    """``exit status 7`` or ``signal 9 (SIGKILL)`` for a process's return code."""
    if returncode is None:
        return "unknown status"
    if returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = "?"
        return f"signal {-returncode} ({name})"
    return f"exit status {returncode}"


# ------------------------------------------------------------------ pipes
def read_exact(fd, n, deadline) -> bytes:
    """Exactly ``n`` bytes from pipe ``fd`` before ``deadline`` (POSIX,
    ``select``): :class:`TimeoutError` past it, :class:`EOFError` at the
    end. Windows has no ``select`` on pipes: the sandbox reads there with a
    thread instead."""
    import select
    buf = bytearray()
    while len(buf) < n:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            raise TimeoutError("no data before the deadline")
        chunk = os.read(fd, min(n - len(buf), 1 << 20))
        if not chunk:
            raise EOFError
        buf += chunk
    return bytes(buf)


def write_all(fd, data, deadline):
    """Write all of ``data`` to pipe ``fd`` before ``deadline`` (a
    ``time.monotonic()`` value); :class:`TimeoutError` when the reader does
    not take it in time (a child that stopped reading), :class:`OSError`
    when it is gone. POSIX: a non-blocking write and ``select``; elsewhere
    a writer thread that is given up on at the deadline."""
    view = memoryview(data)
    if not IS_WINDOWS and enabled("select"):
        import select
        os.set_blocking(fd, False)
        while view:
            try:
                n = os.write(fd, view[:1 << 20])
                view = view[n:]
                continue
            except BlockingIOError:
                pass
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("the student's process did not read its input")
            select.select([], [fd], [], min(left, 1.0))
        return
    box: list = []
    # the thread writes through a copy of the descriptor that it closes
    # itself: given up on at the deadline, it may still be blocked in a write
    # after the caller closed ``fd``, and that number may by then be another
    # pipe's (the next student's) or the results file's
    own = os.dup(fd)

    def writer():
        try:
            with contextlib.suppress(OSError, AttributeError):   # Windows before 3.12
                os.set_blocking(own, True)
            mv = view
            while mv:
                n = os.write(own, mv)
                mv = mv[n:]
            box.append(None)
        except OSError as e:
            box.append(e)
        finally:
            os.close(own)

    th = threading.Thread(target=writer, daemon=True, name="avblocks-lab-writer")
    th.start()
    th.join(max(0.0, deadline - time.monotonic()))
    if th.is_alive():
        raise TimeoutError("the student's process did not read its input")
    if box and box[0] is not None:
        raise box[0]


# ------------------------------------------------------------------ supervised commands
def full_isolation() -> bool:
    """True where a student's process can reach no other process (Landlock
    ABI 6+: no signal, no ptrace, no write outside its folder) and a
    supervisor collects everything it starts: only then may the grader start
    the next student's process while one still runs."""
    return (IS_LINUX and enabled("supervisor") and enabled("subreaper")
            and landlock_abi() >= 6)


class Supervised:
    """``cmd`` run under the supervisor (:func:`supervise`) where the
    platform has one: the command and everything it starts die when
    :meth:`kill` is called *or when this process ends in any way*, even by
    SIGKILL (the supervisor sees its control socket close). Without a
    supervisor (Windows, or switched off) ``cmd`` runs directly in a
    session of its own and :meth:`kill` ends its tree.

    ``popen`` keywords go to :class:`subprocess.Popen` (stdin, stdout, env,
    cwd); ``cleanup``, a folder the supervisor removes once everything is
    dead (the student's temporary folder, also when the grader was killed).
    """

    def __init__(self, cmd, cleanup=None, **popen):
        self.ctrl = None
        self._pid = None
        self._code = None
        self._ended = False
        if IS_WINDOWS or not enabled("supervisor"):
            env = dict(popen.pop("env", None) or os.environ)
            if off():
                env["AVBLOCKS_LAB_DISABLE"] = ",".join(off())
            self.proc = subprocess.Popen(cmd, env=env, **popen, **popen_options())
            self._pid = self.proc.pid
            return
        import socket
        mine, theirs = socket.socketpair()
        sup = [sys.executable, "-I", "-S", "-B", os.path.abspath(__file__), "supervise",
               ",".join(off()) or "-", str(theirs.fileno()), str(cleanup or "-"), "--", *cmd]
        try:
            self.proc = subprocess.Popen(sup, pass_fds=(theirs.fileno(),), **popen)
        except BaseException:
            mine.close()
            raise
        finally:
            theirs.close()
        self.ctrl = mine

    @property
    def supervised(self) -> bool:
        return self.ctrl is not None

    def _line(self, timeout):
        self.ctrl.settimeout(max(0.001, timeout))
        buf = b""
        try:
            while not buf.endswith(b"\n") and len(buf) < 200:
                chunk = self.ctrl.recv(1)
                if not chunk:
                    return None
                buf += chunk
        except OSError:
            return None
        return buf.decode("ascii", "replace").strip()

    def _until(self, prefix, timeout):
        end = time.monotonic() + timeout
        while True:
            line = self._line(end - time.monotonic())
            if line is None:
                return None
            if line.startswith("pid "):
                with contextlib.suppress(ValueError, IndexError):
                    self._pid = int(line.split()[1])
            elif line.startswith("exit "):
                with contextlib.suppress(ValueError):
                    self._code = int(line[5:])
                self._ended = True
            if line.startswith(prefix):
                return line
            if time.monotonic() >= end:
                return None

    def pid(self, timeout=30.0):
        """The command's process id (not the supervisor's)."""
        if self._pid is None and self.ctrl is not None:
            self._until("pid ", timeout)
        return self._pid

    def exit_code(self, timeout=5.0):
        """The command's return code once it ended by itself (None if unknown)."""
        if self.ctrl is None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                return self.proc.wait(timeout)
            return None
        if not self._ended:
            self._until("exit ", timeout)
        return self._code

    def terminate(self, timeout=10.0):
        """Ask the command to stop (SIGTERM; Windows: CTRL_BREAK) and wait
        for it up to ``timeout``; True when it ended."""
        pid = self.pid()
        if pid is None:
            return True
        with contextlib.suppress(OSError):
            if IS_WINDOWS:
                os.kill(pid, signal.CTRL_BREAK_EVENT)
            else:
                os.kill(pid, signal.SIGTERM)
        if self.ctrl is None:
            try:
                self.proc.wait(timeout)
                return True
            except subprocess.TimeoutExpired:
                return False
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with contextlib.suppress(OSError):
                os.kill(pid, 0)
                time.sleep(0.05)
                continue
            return True
        return False

    def kill(self, timeout=10.0):
        """Kill the command with everything it started; its return code when
        it had ended by itself."""
        if self.ctrl is not None:
            with contextlib.suppress(OSError):
                self.ctrl.sendall(b"kill\n")
            if not self._ended:
                self._until("exit ", timeout)
            if not self._ended and self._pid:   # the supervisor is gone: do its work
                kill_tree(self._pid)
            with contextlib.suppress(OSError):
                self.ctrl.close()
        else:
            kill_tree(self.proc.pid)
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        if self.ctrl is None:
            return self.proc.returncode
        return self._code


# ------------------------------------------------------------------ the supervisor
def _ignore(signum, frame):
    """The supervisor's handler of SIGINT, SIGTERM and SIGHUP: nothing (it
    dies only with the grader's control socket or its ``kill``)."""


def supervise(argv):
    """The supervisor (POSIX): ``oscalls.py supervise OFF CTRL_FD CLEANUP -- CMD...``.

    It becomes the subreaper of what it starts (Linux), starts ``CMD`` (the
    student's process) in a new session with its own stdin/stdout (the
    grader's pipes), gives up its copies of them, tells the grader ``pid N``
    on the control socket ``CTRL_FD``, then waits. When the child ends by
    itself, or the grader writes ``kill`` or goes away (end of file), it
    kills the child's session and every descendant it can find (orphans
    come back to it as the subreaper), reaps them, removes the folder
    ``CLEANUP`` (``-``: none), writes ``exit <code>`` (the child's return
    code) and exits."""
    disabled_names, ctrl_fd, cleanup = argv[0], int(argv[1]), argv[2]
    cmd = argv[4:]
    set_off([n for n in disabled_names.split(",") if n and n != "-"])
    import socket
    ctrl = socket.socket(fileno=ctrl_fd)
    sub = become_subreaper()
    # the grader's end going away must not kill us by SIGPIPE before we clean up
    signal.signal(signal.SIGPIPE, signal.SIG_IGN)
    # a handler, not SIG_IGN: an ignored signal stays ignored across execve,
    # and the student's process (and lab 6's emulator) would ignore them too
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, _ignore)
    devnull = os.open(os.devnull, os.O_RDWR)
    try:
        child = subprocess.Popen(cmd, stdin=0, stdout=1, stderr=devnull, close_fds=True,
                                 **popen_options())
    except OSError as e:
        with contextlib.suppress(OSError):
            ctrl.sendall(f"error {e}\n".encode())
        return 3
    os.dup2(devnull, 0)
    os.dup2(devnull, 1)
    with contextlib.suppress(OSError):
        ctrl.sendall(f"pid {child.pid} subreaper {int(sub)}\n".encode())
    import select
    ctrl.setblocking(False)
    code = None
    while code is None:
        try:
            r, _, _ = select.select([ctrl], [], [], 0.05)
        except InterruptedError:
            r = []
        if r:
            try:
                msg = ctrl.recv(64)
            except BlockingIOError:
                msg = b"?"
            except OSError:
                msg = b""
            if not msg or b"kill" in msg:
                break
        code = child.poll()
    kill_tree(child.pid, mine=sub)
    if code is None:
        with contextlib.suppress(Exception):
            child.wait(5)
        code = child.returncode
    if cleanup != "-":
        remove_tree(cleanup)
    reap()
    with contextlib.suppress(OSError):
        ctrl.setblocking(True)
        ctrl.sendall(f"exit {code}\n".encode())
    return 0


if __name__ == "__main__":                       # the supervisor, run as a script
    if len(sys.argv) > 5 and sys.argv[1] == "supervise" and sys.argv[5] == "--":
        sys.exit(supervise(sys.argv[2:]))
    sys.exit(f"usage: {sys.argv[0]} supervise OFF CTRL_FD CLEANUP -- CMD...")
