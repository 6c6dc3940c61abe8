"""Nothing lost, whatever ends a CLI run: real subprocesses, real signals, a
real file-size limit, real unwritable folders.

The scenario integrates a constant 1, so the logged state must equal the
logged time exactly (the independent truth for "the partial file is valid")."""

import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import avblocks as av

SRC = str(Path(av.__file__).resolve().parents[1])

SCENARIO = '''
import os, pathlib
import numpy as np
import avblocks as av

MARK = pathlib.Path(os.environ["AVB_MARK"])


def _mark(t, x):
    if t >= 0.3 and not MARK.exists():
        MARK.write_text(str(t))
    return x


def make_diagram(n=3, t_final=600.0, realtime=1.0):
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.ones((n, 2))), name="c")
    f = d.add(av.blocks.Function(_mark, inputs={"x": (n, 2)}, outputs={"y": (n, 2)}),
              name="f")
    i = d.add(av.blocks.Integrator(np.zeros((n, 2))), name="i")
    d.connect(c.y, f.x)
    d.connect(f.y, i.u)
    sim = {"t_final": t_final, "dt": 0.01, "log": ["i.y"]}
    if realtime:
        sim["realtime"] = realtime
    return d, sim
'''


def _env(mark):
    env = dict(os.environ)
    env["PYTHONPATH"] = SRC + os.pathsep + env.get("PYTHONPATH", "")
    env["AVB_MARK"] = str(mark)
    env["MPLBACKEND"] = "Agg"
    return env


def _start(tmp_path, *extra, preexec=None):
    scen = tmp_path / "slow.py"
    scen.write_text(SCENARIO)
    mark = tmp_path / "started"
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "avblocks", "run", str(scen), "--out", str(out),
           "--quiet", *extra]
    p = subprocess.Popen(cmd, env=_env(mark), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, start_new_session=True,
                         preexec_fn=preexec)
    return p, mark, out


def _wait_for(mark, p, timeout=60):
    t_end = time.monotonic() + timeout
    while not mark.exists():
        if p.poll() is not None:
            raise AssertionError("run ended early: " + p.stderr.read())
        if time.monotonic() > t_end:
            p.kill()
            raise AssertionError("the run never started")
        time.sleep(0.02)
    time.sleep(0.2)


def _check_partial(out):
    res = av.Results.load(out / "results.nc")
    assert len(res.t) > 30 and res.t[-1] >= 0.3
    assert res.t[-1] < 600
    # the file is complete and valid: x(t) = t for every agent, every sample
    np.testing.assert_allclose(res["i.y"][:, :, 0], np.repeat(res.t[:, None], 3, 1),
                               atol=1e-9)
    assert res.meta["interrupted"] is True
    return res


@pytest.mark.parametrize("sig,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143),
                                      (signal.SIGHUP, 129)])
def test_signal_saves_partial_results_and_exits_128_plus_signal(tmp_path, sig, code):
    p, mark, out = _start(tmp_path)
    _wait_for(mark, p)
    p.send_signal(sig)
    stdout, stderr = p.communicate(timeout=60)
    assert p.returncode == code, stderr
    res = _check_partial(out)
    name = signal.Signals(sig).name
    assert res.meta["interrupted_by"] == name
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["interrupted_by"] == name
    assert summary["simulated_s"] == pytest.approx(res.t[-1])
    assert f"interrupted by {name}" in stderr and "were saved to" in stderr
    assert "Traceback" not in stderr
    assert "status        interrupted" in stdout
    assert not list(out.glob(".*part*"))


def test_repeated_ctrl_c_does_not_lose_the_results(tmp_path):
    p, mark, out = _start(tmp_path)
    _wait_for(mark, p)
    for _ in range(6):          # an impatient user
        try:
            os.kill(p.pid, signal.SIGINT)
        except ProcessLookupError:
            break
        time.sleep(0.01)
    _stdout, stderr = p.communicate(timeout=60)
    assert p.returncode == 130, stderr
    assert "Traceback" not in stderr
    _check_partial(out)
    assert json.loads((out / "summary.json").read_text())["status"] == "interrupted"


def test_unwritable_output_is_refused_before_simulating(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    p, mark, _ = _start(tmp_path, "--out", str(blocker / "sub"))
    stdout, stderr = p.communicate(timeout=60)
    assert p.returncode == 2
    assert "output folder" in stderr and "Traceback" not in stderr
    assert not mark.exists()        # nothing was simulated


def _read_only_folder(tmp_path):
    """A folder the run cannot write: chmod for a normal user; as root a
    read-only tmpfs, or where mounting is not allowed /proc/1 (an existing
    folder of a file system where nobody, root included, can create files)."""
    ro = tmp_path / "ro"
    ro.mkdir()
    if os.geteuid() != 0:
        ro.chmod(0o555)
        return ro, None
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(ro)],
                       capture_output=True)
    if r.returncode == 0:
        return ro, ro
    return Path("/proc/1"), None


def test_read_only_output_folder_is_refused_before_simulating(tmp_path):
    ro, mounted = _read_only_folder(tmp_path)
    try:
        p, mark, _ = _start(tmp_path, "--out", str(ro))
        _stdout, stderr = p.communicate(timeout=60)
        assert p.returncode == 2, stderr
        assert "not writable" in stderr and "Traceback" not in stderr
        assert not mark.exists()
    finally:
        if mounted is not None:
            subprocess.run(["umount", str(mounted)], check=False)
        elif ro.parent == tmp_path:
            ro.chmod(0o755)


def _limit_file_size():
    resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, 20_000))


def test_full_disk_gives_a_clear_error_and_no_corrupt_file(tmp_path):
    # a finished run whose results (about 100 kB) exceed a 20 kB file-size limit
    out = tmp_path / "out"
    out.mkdir()
    old = out / "results.nc"
    old.write_bytes(b"previous results")
    p, _mark, out = _start(tmp_path, "--set", "t_final=20", "--set", "realtime=0",
                           preexec=_limit_file_size)
    stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == 3, stderr
    assert "Traceback" not in stderr and "egmentation" not in stderr
    assert "could not write" in stderr and "file size limit" in stderr
    assert "could NOT be saved" in stderr
    assert "were saved" not in stderr
    assert old.read_bytes() == b"previous results"     # untouched, not half-overwritten
    assert not list(out.glob(".*part*"))                  # no temporary left behind
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "complete" and summary["write_errors"]
    assert str(old) not in summary["files"]


def test_simulation_error_message_only_claims_saved_when_saved(tmp_path):
    scen = tmp_path / "bad.py"
    scen.write_text('''
import numpy as np
import avblocks as av

def _boom(t, x):
    return x / 0.0 if t > 0.5 else x

def make_diagram():
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.ones((2, 2))), name="c")
    f = d.add(av.blocks.Function(_boom, inputs={"x": (2, 2)}, outputs={"y": (2, 2)}),
              name="f")
    i = d.add(av.blocks.Integrator(np.zeros((2, 2))), name="i")
    d.connect(c.y, f.x)
    d.connect(f.y, i.u)
    return d, {"t_final": 2.0, "dt": 0.1, "log": ["i.y"]}
''')
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "avblocks", "run", str(scen), "--out",
                        str(out), "--quiet"], env=_env(tmp_path / "m"),
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 3
    assert "block 'f'" in r.stderr and "were saved to" in r.stderr
    res = av.Results.load(out / "results.nc")
    np.testing.assert_allclose(res["i.y"][:, 0, 0], res.t, atol=1e-12)
    assert res.t[-1] == pytest.approx(0.5)
    # the same failure under a file-size limit: the message must not claim a save
    out2 = tmp_path / "out2"
    r = subprocess.run([sys.executable, "-m", "avblocks", "run", str(scen), "--out",
                        str(out2), "--quiet"], env=_env(tmp_path / "m"),
                       capture_output=True, text=True, timeout=120,
                       preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE,
                                                             (2000, 2000)))
    assert r.returncode == 3
    assert "were saved" not in r.stderr and "could NOT be saved" in r.stderr
    assert not (out2 / "results.nc").exists()


class _StopFails(av.Block):
    """A side-effect block whose on_stop raises."""

    side_effects = True

    def __init__(self):
        super().__init__()
        self.declare_input("u", (2, 2))
        self.stopped = False

    def output(self, t, x, u, xp):
        return {}

    def on_stop(self):
        self.stopped = True
        raise OSError("disk went away")


def _diagram(fail_at=None):
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.ones((2, 2))), name="c")
    i = d.add(av.blocks.Integrator(np.zeros((2, 2))), name="i")
    s = _StopFails()
    h = d.add(s, name="sink")
    d.connect(c.y, i.u)
    d.connect(i.y, h.u)
    return d, s


def test_on_stop_failure_never_replaces_the_results():
    d, s = _diagram()
    with pytest.warns(av.SimulationWarning, match="disk went away"):
        res = av.simulate(d, t_final=1.0, dt=0.1, log=["i.y"])
    assert s.stopped
    np.testing.assert_allclose(res["i.y"][-1], np.ones((2, 2)))
    assert "sink" in res.meta["on_stop_errors"][0]


def test_on_stop_failure_never_replaces_the_real_error():
    d, s = _diagram()
    f = d.add(av.blocks.Function(lambda t, x: x * np.nan if t > 0.35 else x,
                                 inputs={"x": (2, 2)}, outputs={"y": (2, 2)}), name="f")
    d.connect(d["i"].y, f.x)
    with pytest.raises(av.SimulationError, match="block 'f'") as ei:
        av.simulate(d, t_final=1.0, dt=0.1, log=["i.y", "f.y"])
    assert s.stopped
    assert ei.value.results.t[-1] == pytest.approx(0.3)
    assert "disk went away" in ei.value.on_stop_errors[0]
