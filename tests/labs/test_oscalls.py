"""The grader's platform calls (``avblocks.labs.oscalls``) and their fallbacks.

Each fallback is forced with ``oscalls.disabled(...)`` (what a platform
without the feature would take) and checked against an independent view
of the system: psutil for process trees and liveness, ``resource`` read
back in the limited process, the file system for Landlock. The whole
grader is then run with every feature off: the path Windows and old
kernels take, minus the Windows-only calls (``taskkill``,
``CREATE_NEW_PROCESS_GROUP``), which cannot run here."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import psutil
import pytest

from avblocks.labs import get, oscalls, run_checks

HERE = Path(__file__).resolve().parent
SRC = HERE.parents[1] / "src"
SOLUTION = HERE / "solutions" / "lab1_kinematics.py"
posix = pytest.mark.skipif(os.name != "posix", reason="POSIX process calls")


def _tree(token):
    """A process with a child and a grandchild, all sleeping with ``token``."""
    code = ("import subprocess, sys, time\n"
            "subprocess.Popen([sys.executable, '-c', 'import subprocess, sys, time; "
            "subprocess.Popen([sys.executable, \"-c\", \"import time; time.sleep(60)\", "
            f"\"{token}\"]); time.sleep(60)', '{token}'])\n"
            "time.sleep(60)\n")
    p = subprocess.Popen([sys.executable, "-c", code, token], start_new_session=True)
    end = time.monotonic() + 30
    while time.monotonic() < end:
        kids = psutil.Process(p.pid).children(recursive=True)
        if len(kids) >= 2:
            return p
        time.sleep(0.05)
    raise AssertionError("the tree did not start")


def _alive(pids):
    out = []
    for pid in pids:
        try:
            if psutil.Process(pid).status() != psutil.STATUS_ZOMBIE:
                out.append(pid)
        except psutil.NoSuchProcess:
            pass
    return out


def test_status_text():
    assert oscalls.status_text(7) == "exit status 7"
    assert oscalls.status_text(-signal.SIGKILL) == "signal 9 (SIGKILL)"
    assert oscalls.status_text(None) == "unknown status"


@posix
@pytest.mark.parametrize("off", [(), ("proc",), ("proc", "psutil")])
def test_descendants_by_every_path_agree_with_psutil(off):
    p = _tree(uuid.uuid4().hex)
    try:
        truth = sorted(c.pid for c in psutil.Process(p.pid).children(recursive=True))
        with oscalls.disabled(*off):
            assert sorted(oscalls.descendants(p.pid)) == truth
    finally:
        oscalls.kill_tree(p.pid)
        p.wait(10)


@posix
@pytest.mark.parametrize("off", [(), ("killpg",), ("killpg", "proc", "psutil")])
def test_kill_tree_leaves_nothing(off):
    p = _tree(uuid.uuid4().hex)
    everyone = [p.pid] + [c.pid for c in psutil.Process(p.pid).children(recursive=True)]
    with oscalls.disabled(*off):
        oscalls.kill_tree(p.pid)
    p.wait(10)
    end = time.monotonic() + 10
    while _alive(everyone) and time.monotonic() < end:
        time.sleep(0.05)
    assert _alive(everyone) == []


@pytest.mark.parametrize("off", [(), ("select",)])
def test_write_all_gives_up_on_a_reader_that_does_not_read(off):
    r, w = os.pipe()
    try:
        with oscalls.disabled(*off):
            oscalls.write_all(w, b"x" * 100, time.monotonic() + 5)      # fits in the pipe
            assert os.read(r, 1000) == b"x" * 100
            t0 = time.monotonic()
            with pytest.raises(TimeoutError):
                oscalls.write_all(w, b"y" * (4 << 20), time.monotonic() + 0.5)
            assert time.monotonic() - t0 < 5
    finally:
        os.close(r)
        os.close(w)


def test_limits_without_setrlimit_are_reported_not_set():
    with oscalls.disabled("resource"):
        got = oscalls.apply_limits(memory_mb=512, cpu_s=10, processes=8, files=64, file_mb=1)
    assert got == {k: "not set: setrlimit switched off"
                   for k in ("memory", "cpu", "processes", "open_files", "file_size")}


def _in_child(code):
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                       env={**os.environ, "PYTHONPATH": str(SRC)})
    assert p.returncode == 0, p.stderr
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")]
    assert len(lines) == 1, (p.stdout, p.stderr)
    return json.loads(lines[0][7:])


@posix
def test_limits_are_set_as_reported():
    out = _in_child(
        "import json, resource\n"
        "from avblocks.labs import oscalls\n"
        "said = oscalls.apply_limits(memory_mb=3000, cpu_s=77, files=99, file_mb=5)\n"
        "got = {k: resource.getrlimit(getattr(resource, k)) for k in "
        "('RLIMIT_AS', 'RLIMIT_CPU', 'RLIMIT_NOFILE', 'RLIMIT_FSIZE', 'RLIMIT_CORE')}\n"
        "raised = {}\n"
        "for k in got:\n"                 # a process may raise a soft limit to its hard one
        "    rl = getattr(resource, k)\n"
        "    try:\n"
        "        resource.setrlimit(rl, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))\n"
        "    except (ValueError, OSError):\n"
        "        resource.setrlimit(rl, (resource.getrlimit(rl)[1],) * 2)\n"
        "    raised[k] = resource.getrlimit(rl)[0]\n"
        "print('RESULT ' + json.dumps([said, got, raised]))\n")
    said, got, raised = out
    soft = {"RLIMIT_AS": 3000 * 2 ** 20, "RLIMIT_CPU": 77, "RLIMIT_NOFILE": 99,
            "RLIMIT_FSIZE": 5 * 2 ** 20, "RLIMIT_CORE": 0}
    assert {k: v[0] for k, v in got.items()} == soft
    # each hard limit is the soft one (CPU: SIGKILL 5 s after SIGXCPU), so the
    # process cannot raise them again (as root it could: the grader's child
    # drops CAP_SYS_RESOURCE with every other capability, tested below)
    assert {k: v[1] for k, v in got.items()} == {**soft, "RLIMIT_CPU": 82}
    if os.geteuid() != 0:
        assert raised == {**soft, "RLIMIT_CPU": 82}
    assert said["memory"].startswith("3000 MiB") and said["cpu"] == "77 s of CPU time " \
        "(RLIMIT_CPU)" and said["open_files"] == "99 open files (RLIMIT_NOFILE)"


@posix
def test_huge_limits_are_reported_not_a_crash():
    out = _in_child(
        "import json\n"
        "from avblocks.labs import oscalls\n"
        "said = oscalls.apply_limits(cpu_s=1e300, memory_mb=2 ** 40)\n"
        "x = sum(range(10 ** 6))\n"              # some CPU time: no SIGXCPU at once
        "print('RESULT ' + json.dumps(said))\n")
    assert out["cpu"] == "1000000000 s of CPU time (RLIMIT_CPU)"
    assert out["memory"] == f"{2 ** 40} MiB of address space (RLIMIT_AS)"


def test_landlock_switched_off_is_reported(tmp_path):
    with oscalls.disabled("landlock"):
        assert oscalls.landlock_abi() == 0
        got = oscalls.restrict_writes(tmp_path)
    assert set(got.values()) == {"not restricted: Landlock switched off"}


@pytest.mark.skipif(oscalls.landlock_abi() < 1, reason="needs Landlock (Linux 5.13+)")
def test_landlock_allows_writes_only_in_the_folder(tmp_path):
    inside, outside = tmp_path / "in", tmp_path / "out"
    inside.mkdir()
    outside.mkdir()
    (outside / "old.txt").write_text("old")
    out = _in_child(
        "import json, os\n"
        "from avblocks.labs import oscalls\n"
        f"said = oscalls.restrict_writes({str(inside)!r})\n"
        "res = {}\n"
        f"for name, path in (('in', {str(inside / 'a.txt')!r}), "
        f"('out', {str(outside / 'b.txt')!r}), ('old', {str(outside / 'old.txt')!r}), "
        "('null', os.devnull)):\n"
        "    try:\n"
        "        open(path, 'w').write('x'); res[name] = 'written'\n"
        "    except OSError as e:\n"
        "        res[name] = type(e).__name__\n"
        "try:\n"
        "    os.kill(os.getppid(), 0); res['signal'] = 'sent'\n"
        "except OSError as e:\n"
        "    res['signal'] = type(e).__name__\n"
        "print('RESULT ' + json.dumps([said, res]))\n")
    said, res = out
    assert said["files"].startswith("writes only inside its own temporary folder")
    assert res["in"] == res["null"] == "written"
    assert res["out"] == res["old"] == "PermissionError"
    assert (outside / "old.txt").read_text() == "old" and not (outside / "b.txt").exists()
    if oscalls.landlock_abi() >= 6:
        assert res["signal"] == "PermissionError"


@posix
@pytest.mark.parametrize("off", [(), ("supervisor",)])
def test_supervised_commands_die_with_everything_they_started(off):
    token = uuid.uuid4().hex
    code = ("import os, subprocess, sys, time\n"
            f"T = {token!r}\n"
            "subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)', T])\n"
            "if os.fork() == 0:\n"                     # a daemon, out of the session
            "    os.setsid()\n"
            "    if os.fork() == 0:\n"
            "        os.execv(sys.executable, [sys.executable, '-c', "
            "'import time; time.sleep(60)', T])\n"
            "    os._exit(0)\n"
            "time.sleep(60)\n")
    with oscalls.disabled(*off):
        run = oscalls.Supervised([sys.executable, "-c", code, token],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        end = time.monotonic() + 30
        while len(_marked(token)) < 3 and time.monotonic() < end:
            time.sleep(0.05)
        assert len(_marked(token)) >= 3     # itself, its subprocess, the daemon
        time.sleep(0.3)                      # the daemon's parent has exited
        run.kill()
    time.sleep(0.3)
    left = _marked(token)
    try:
        if off:             # without a subreaper, the double-forked daemon escapes
            assert len(left) <= 1
        else:
            assert left == []
    finally:
        for pid in left:
            psutil.Process(pid).kill()


def _marked(token):
    out = []
    for p in psutil.process_iter(["cmdline", "status"]):
        if p.info["status"] != psutil.STATUS_ZOMBIE and token in (p.info["cmdline"] or []):
            out.append(p.pid)
    return out


FORKS = ("\nimport os as _os, sys as _sys\n"
         "if _os.fork() == 0:\n"
         "    _os.execv(_sys.executable, [_sys.executable, '-c', 'import time; "
         "time.sleep(60)', 'TOKEN'])\n")


@posix
def test_the_grader_with_every_feature_off(tmp_path):
    """The fallbacks together: no supervisor (the child started directly,
    in no session of its own), no setrlimit, no Landlock, no select (reader
    and writer threads), no killpg, no /proc: an honest file still passes,
    a wrong one fails with its message, the report says what was not set,
    and a forked grandchild is still killed (found in the process tree)."""
    token = uuid.uuid4().hex
    f = tmp_path / "forks.py"
    f.write_text(SOLUTION.read_text() + FORKS.replace("TOKEN", token))
    w = tmp_path / "wrong.py"
    w.write_text(SOLUTION.read_text().replace("v * xp.sin(th), w]", "v * xp.sin(th), -w]"))
    with oscalls.disabled(*oscalls.FEATURES):
        good = run_checks(get(1), f, timeout=30)
        bad = run_checks(get(1), w, timeout=30)
    assert good.passed, good.text()
    assert good.limits["memory"] == "not set: setrlimit switched off"
    assert good.limits["files"] == "not restricted: Landlock switched off"
    assert not bad.passed and "port `pose (its rate, derivative)`" in bad.text()
    assert _marked(token) == []


def test_a_writer_given_up_on_never_writes_into_a_reused_descriptor(tmp_path):
    """Without select (Windows), write_all's thread outlives its deadline.
    The caller then closes the pipe (the student's process is killed, its
    end closes too), and the descriptor's number comes back for the next
    file the grader opens (the next student's pipe, a results file): what
    the old thread had left to write must not land there."""
    r, w = os.pipe()
    with oscalls.disabled("select"):
        with pytest.raises(TimeoutError):
            oscalls.write_all(w, b"y" * (4 << 20), time.monotonic() + 0.3)
    os.close(w)
    results = tmp_path / "results.json"
    fd = os.open(results, os.O_WRONLY | os.O_CREAT)   # the lowest free number: w's
    try:
        os.close(r)                   # the reader is gone: the blocked write returns
        time.sleep(0.5)
    finally:
        os.close(fd)
    assert fd != w or results.stat().st_size == 0, \
        f"the old writer wrote {results.stat().st_size} bytes into the next file"


def _restricted(code, *setup):
    """Run ``code`` in a child after ``setup`` (calls of oscalls, as the
    grader's child makes them); its RESULT."""
    return _in_child("import json, os, sys\nfrom avblocks.labs import oscalls\n"
                     + "".join(f"said_{i} = oscalls.{c}\n" for i, c in enumerate(setup))
                     + code)


@pytest.mark.skipif(oscalls.seccomp_arch() is None and not os.environ.get("CI"),
                    reason="seccomp filter for Linux x86-64 and arm64 only")
def test_seccomp_refuses_sockets_and_mode_changes_and_nothing_else(tmp_path):
    f = tmp_path / "f.txt"
    f.write_text("x")
    res = _restricted(
        "import socket\nres = {'said': said_0}\n"
        "def t(name, fn):\n"
        "    try:\n"
        "        fn(); res[name] = 'done'\n"
        "    except OSError as e:\n"
        "        res[name] = e.errno\n"
        "t('udp', lambda: socket.socket(socket.AF_INET, socket.SOCK_DGRAM))\n"
        "t('unix', lambda: socket.socket(socket.AF_UNIX))\n"
        "t('pair', lambda: socket.socketpair())\n"
        f"t('chmod', lambda: os.chmod({str(f)!r}, 0o600))\n"
        f"t('utime', lambda: os.utime({str(f)!r}, (0, 0)))\n"
        f"t('read', lambda: open({str(f)!r}).read())\n"
        f"t('write', lambda: open({str(f)!r}, 'a').write('y'))\n"
        "import subprocess\n"
        "res['run'] = subprocess.run([sys.executable, '-c', 'import socket; "
        "socket.socket()'], capture_output=True, text=True).stderr.splitlines()[-1]\n"
        "print('RESULT ' + json.dumps(res))\n", "restrict_syscalls()")
    import errno
    assert res.pop("said")["sockets"].startswith("no socket of any kind")
    # refused with EPERM; a socket pair (no address: only itself) and files are fine;
    # the filter holds in what the process starts (the socket call there fails)
    assert res == {"udp": errno.EPERM, "unix": errno.EPERM, "pair": "done",
                   "chmod": errno.EPERM, "utime": errno.EPERM, "read": "done",
                   "write": "done",
                   "run": "PermissionError: [Errno 1] Operation not permitted"}
    assert f.stat().st_mode & 0o777 != 0o600 and f.stat().st_mtime > 0


def test_seccomp_switched_off_is_reported():
    with oscalls.disabled("seccomp"):
        assert oscalls.seccomp_arch() is None
        got = oscalls.restrict_syscalls()
    assert set(got.values()) == {"not restricted: seccomp switched off"}


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux capabilities")
def test_dropped_capabilities_stay_dropped():
    res = _restricted(
        "import resource\n"
        "st = open('/proc/self/status').read()\n"
        "caps = {k: int(v, 16) for k, v in (ln.split(':') for ln in st.splitlines() "
        "if ln.startswith('Cap'))}\n"
        "raised = 'no'\n"
        "resource.setrlimit(resource.RLIMIT_NOFILE, (64, 64))\n"
        "try:\n"
        "    resource.setrlimit(resource.RLIMIT_NOFILE, (128, 128)); raised = 'yes'\n"
        "except (ValueError, OSError):\n"
        "    pass\n"
        "import subprocess\n"
        "again = subprocess.run([sys.executable, '-c', \"print(open('/proc/self/status')"
        ".read().split('CapEff:')[1].split()[0])\"], capture_output=True, text=True).stdout\n"
        "print('RESULT ' + json.dumps([said_0, caps, raised, int(again, 16)]))\n",
        "drop_capabilities()")
    said, caps, raised, again = res
    assert caps["CapEff"] == caps["CapPrm"] == caps["CapInh"] == caps.get("CapAmb", 0) == 0
    if os.geteuid() == 0:                 # only a process with CAP_SETPCAP empties it
        assert caps["CapBnd"] == 0
    assert raised == "no" and again == 0          # not even by running a program
    assert said == ("every capability dropped (the grader runs as root)" if os.geteuid() == 0
                    else "none (the grader does not run as root)")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_DUMPABLE")
def test_an_undumpable_grader_hides_its_environment():
    """While the grader grades, a process without CAP_SYS_PTRACE (the
    student's, whose capabilities are dropped) cannot read its environment."""
    import ctypes
    libc = ctypes.CDLL(None)
    code = ("import os\nfrom avblocks.labs import oscalls\noscalls.drop_capabilities()\n"
            "try:\n    open(f'/proc/{os.getppid()}/environ', 'rb').read(); print('read')\n"
            "except OSError:\n    print('refused')\n")
    env = {**os.environ, "PYTHONPATH": str(SRC)}

    def child():
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              env=env, timeout=60).stdout.strip()

    assert libc.prctl(3, 0, 0, 0, 0) == 1
    with oscalls.undumpable():
        assert libc.prctl(3, 0, 0, 0, 0) == 0
        assert child() == "refused"
    assert libc.prctl(3, 0, 0, 0, 0) == 1              # put back
    if os.geteuid() != 0:
        assert child() == "read"          # the same user reads a dumpable process's


@pytest.mark.skipif(oscalls.landlock_abi() < 1, reason="needs Landlock (Linux 5.13+)")
def test_landlock_reads_only_the_installation_and_its_own_folder(tmp_path):
    inside, outside = tmp_path / "in", tmp_path / "out"
    inside.mkdir()
    outside.mkdir()
    (outside / "secret.py").write_text("answer = 42\n")
    (inside / "mine.txt").write_text("mine")
    res = _restricted(
        "res = {}\n"
        "def t(name, fn):\n"
        "    try:\n"
        "        fn(); res[name] = 'done'\n"
        "    except OSError as e:\n"
        "        res[name] = type(e).__name__\n"
        f"t('secret', lambda: open({str(outside / 'secret.py')!r}).read())\n"
        f"t('list', lambda: os.listdir({str(outside)!r}))\n"
        f"t('mine', lambda: open({str(inside / 'mine.txt')!r}).read())\n"
        "t('shadow', lambda: open('/etc/shadow').read() if os.path.exists('/etc/shadow') "
        "else (_ for _ in ()).throw(PermissionError()))\n"
        "import importlib\n"
        "t('stdlib', lambda: importlib.import_module('xml.dom.minidom'))\n"
        "t('numpy', lambda: importlib.import_module('numpy.polynomial.hermite'))\n"
        "t('avblocks', lambda: importlib.import_module('avblocks.controllers'))\n"
        "import subprocess\n"
        "t('run', lambda: subprocess.run([sys.executable, '-c', 'import numpy'], "
        "check=True))\n"
        "print('RESULT ' + json.dumps([said_0, res]))\n",
        f"restrict_writes({str(inside)!r})")
    said, res = res
    assert said["reads"].startswith("reads only its own folder")
    assert res == {"secret": "PermissionError", "list": "PermissionError", "mine": "done",
                   "shadow": "PermissionError", "stdlib": "done", "numpy": "done",
                   "avblocks": "done", "run": "done"}


@pytest.mark.skipif(oscalls.seccomp_arch() is None and not os.environ.get("CI"),
                    reason="seccomp filter for Linux x86-64 and arm64 only")
def test_seccomp_refuses_signals_to_the_protected_processes_only():
    """The grader and the supervisor (here: the test process, the child's
    parent), their group and ``-1`` are protected; the child's own process,
    group and children are not."""
    me = os.getpid()
    res = _restricted(
        "import signal, subprocess\nres = {}\n"
        "def t(name, fn):\n"
        "    try:\n"
        "        fn(); res[name] = 'sent'\n"
        "    except OSError as e:\n"
        "        res[name] = e.errno\n"
        f"t('parent', lambda: os.kill({me}, 0))\n"
        f"t('parent group', lambda: os.killpg(os.getpgid({me}), 0))\n"
        "t('everyone', lambda: os.kill(-1, 0))\n"
        f"t('thread', lambda: signal.pthread_kill(__import__('threading').get_ident(), 0))\n"
        "t('self', lambda: os.kill(os.getpid(), 0))\n"
        "kid = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(30)'])\n"
        "t('child', lambda: kid.kill())\n"
        "kid.wait()\n"
        "res['child status'] = kid.returncode\n"
        "print('RESULT ' + json.dumps(res))\n",
        f"restrict_syscalls([{me}, -os.getpgid({me}), -1])")
    import errno
    assert res == {"parent": errno.EPERM, "parent group": errno.EPERM,
                   "everyone": errno.EPERM, "thread": "sent", "self": "sent", "child": "sent",
                   "child status": -9}


@posix
def test_a_supervised_command_starts_with_the_default_signal_handlers(tmp_path):
    """The supervisor ignores SIGINT, SIGTERM and SIGHUP (a Ctrl-C in the
    grader's terminal is the grader's to handle), but by a handler, not by
    SIG_IGN, which a program inherits: the student's process ignored them."""
    out = tmp_path / "signals.txt"
    code = ("import signal, sys\nopen(sys.argv[1], 'w').write(' '.join(str(int(signal."
            "getsignal(s) is signal.default_int_handler or signal.getsignal(s) == "
            "signal.SIG_DFL)) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)))\n")
    run = oscalls.Supervised([sys.executable, "-c", code, str(out)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        assert run.exit_code(30) == 0
    finally:
        run.kill()
    assert out.read_text() == "1 1 1"


@posix
def test_remove_tree_whatever_the_depth_and_modes(tmp_path):
    """What a student may leave in its own folder: folders nested deeper
    than Python's recursion limit (shutil.rmtree raised RecursionError and
    ended the grader's run), a folder nobody may list, a folder holding a
    file that may not be written, a link to a folder outside (never
    followed: what it points at stays)."""
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "keep.txt").write_text("keep")
    top = tmp_path / "student"
    top.mkdir()
    try:
        _remove_tree_case(top, outside)
    finally:                # never leave pytest a tree its own clean-up cannot remove
        oscalls.remove_tree(top)


def _remove_tree_case(top, outside):
    fd = os.open(top, os.O_RDONLY | os.O_DIRECTORY)
    for _ in range(1200):                             # (os.makedirs recurses too)
        os.mkdir("d", dir_fd=fd)
        fd, old = os.open("d", os.O_RDONLY | os.O_DIRECTORY, dir_fd=fd), fd
        os.close(old)
    os.close(os.open("bottom.txt", os.O_WRONLY | os.O_CREAT, dir_fd=fd))
    os.close(fd)
    with pytest.raises(RecursionError):               # what the grader used
        import shutil
        shutil.rmtree(top)
    (top / "shut").mkdir(mode=0)
    (top / "ro").mkdir()
    (top / "ro" / "f.txt").write_text("x")
    (top / "ro" / "shut").mkdir(mode=0)               # moving it up needs its own modes
    (top / "ro").chmod(0o500)
    (top / "link").symlink_to(outside)
    assert oscalls.remove_tree(top) is True
    assert not top.exists() and (outside / "keep.txt").read_text() == "keep"
    assert oscalls.remove_tree(top) is True           # gone already: fine
