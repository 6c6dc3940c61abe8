"""Compiled runs split over several devices (the CPU split into two JAX
devices, in a subprocess): a run split along its agent axis and an
ensemble split along its run axis give the one-device results, and
avblocks starting JAX asks for one CPU device per core."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

import avblocks as av
from avblocks.core.errors import ParameterError

if os.environ.get("CI"):
    import jax  # noqa: F401 - in CI the jax extra is installed: never skip
else:
    pytest.importorskip("jax")
pytestmark = pytest.mark.jax

SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    import avblocks as av
    from avblocks.core.compiled import _jax, devices
    jax = _jax.jax()
    out = {"devices": len(jax.devices()), "expected": devices.default_cpu_devices()}

    def w1(p0, waypoints):
        d = av.Diagram()
        f = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
        c = d.add(av.controllers.PointToPoint(waypoints, gain=0.8, v_max=1.5),
                  name="drive")
        d.connect(f.pose, c.pose)
        d.connect(c.cmd, f.cmd)
        return d, f, c

    if len(sys.argv) > 1:
        rng = np.random.default_rng(4)
        n = 256
        p0 = np.column_stack([rng.uniform(0, 30, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
        d, f, c = w1(p0, rng.uniform(0, 30, (n, 1, 2)))
        kw = dict(dt=0.01, solver="rk4", log=[f.pose, c.done], log_every=10)
        split = av.compile(d, 4.0, **kw)
        one = av.compile(d, 4.0, devices=1, **kw)
        a, b = split(), one()
        ref = av.simulate(d, 4.0, progress=False, **kw)
        out["split_key"] = list(map(str, split._single.key))
        out["split_vs_one"] = float(np.abs(a[f.pose] - b[f.pose]).max())
        out["split_vs_numpy"] = float(np.abs(a[f.pose] - ref[f.pose]).max())
        out["done_equal"] = bool(np.array_equal(a[c.done], ref[c.done]))
        gains = np.linspace(0.3, 1.2, 6)
        small, f2, c2 = w1(p0[:5], rng.uniform(0, 30, (5, 1, 2)))
        runner = av.compile(small, 3.0, dt=0.01, solver="rk4", log=[f2.pose], log_every=10)
        ens = runner.ensemble(params={"drive.gain": gains[:, None] * np.ones((6, 5))})
        worst = 0.0
        for r, g in enumerate(gains):
            single = av.simulate(small, 3.0, dt=0.01, solver="rk4", log=[f2.pose],
                                 log_every=10, progress=False,
                                 params={"drive.gain": g * np.ones(5)})
            worst = max(worst, float(np.abs(ens[f2.pose][r] - single[f2.pose]).max()))
        out["ensemble_chunk"] = ens.meta["chunk_size"]
        # a law that gathers each agent's waypoint from a flattened table:
        # split, XLA would exchange data every stage; the runner must notice
        # and run on one device instead, with the same results
        g, f3, c3 = w1(p0, rng.uniform(0, 30, (n, 3, 2)))
        kw3 = dict(dt=0.05, solver="rk4", log=[f3.pose], log_every=10)
        r3 = av.compile(g, 20.0, **kw3)
        before = r3._single.key[0]
        a3 = r3()
        out["gather_keys"] = [before, r3._single.key[0]]
        out["gather_vs_numpy"] = float(np.abs(
            a3[f3.pose] - av.simulate(g, 20.0, progress=False, **kw3)[f3.pose]).max())
        out["ensemble_vs_numpy"] = worst
    print(json.dumps(out))
""")


def _run(env_extra, *args):
    env = {k: v for k, v in os.environ.items() if k != "JAX_NUM_CPU_DEVICES"}
    env.update(env_extra)
    p = subprocess.run([sys.executable, "-c", SCRIPT, *args], capture_output=True,
                       text=True, env=env, timeout=240)
    assert p.returncode == 0, p.stderr[-2000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_split_runs_equal_one_device_runs():
    out = _run({"JAX_NUM_CPU_DEVICES": "2"}, "check")
    assert out["devices"] == 2
    assert out["split_key"][0] == "split"           # the agent axis was divided
    assert out["split_vs_one"] <= 1e-12
    assert out["split_vs_numpy"] <= 1e-9
    assert out["done_equal"]
    assert out["ensemble_chunk"] % 2 == 0           # whole runs per device
    assert out["ensemble_vs_numpy"] <= 1e-9
    assert out["gather_keys"] == ["split", "one"]
    assert out["gather_vs_numpy"] <= 1e-9


def test_avblocks_starting_jax_asks_for_one_cpu_device_per_core():
    out = _run({})
    assert out["devices"] == out["expected"]


def test_jax_num_cpu_devices_is_respected():
    out = _run({"JAX_NUM_CPU_DEVICES": "1"})
    assert out["devices"] == 1


def test_bad_devices_are_refused():
    d = av.Diagram()
    c = d.add(av.blocks.Constant([[1.0]]), name="c")
    i = d.add(av.blocks.Integrator([[0.0]]), name="i")
    d.connect(c.y, i.u)
    import jax
    n = len(jax.local_devices())
    with pytest.raises(ParameterError, match="devices"):
        av.compile(d, 1.0, dt=0.1, devices=n + 1)
    with pytest.raises(ParameterError, match="devices"):
        av.compile(d, 1.0, dt=0.1, devices="gpu0")
    with pytest.raises(ParameterError, match="devices"):
        av.compile(d, 1.0, dt=0.1, devices=0)
    r = av.compile(d, 1.0, dt=0.1, devices=1, log=[i.y])
    assert float(r()[i.y][-1, 0, 0]) == pytest.approx(1.0, abs=1e-12)
