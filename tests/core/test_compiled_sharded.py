"""One swarm across devices (``compile(..., shard="agents")``): a run whose
agents are split over four CPU devices (XLA's forced host devices, in a
child process) equals the one-device run -- positions to 1e-9 m, the
neighbour sets exactly -- while agents move between the devices' strips
of space and keep neighbours on other devices (the halo); the traced
searches alone (``nearest``, ``within``, ``candidates``) give the
one-device answers on clouds crowded at the strips' borders; an ensemble
split over the devices by runs equals the one-device ensemble."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import avblocks as av

if os.environ.get("CI"):
    import jax  # noqa: F401  (in CI the jax extra is installed: never skip)
else:
    pytest.importorskip("jax")
pytestmark = pytest.mark.jax

CHILD = r'''
import json, os
os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=4"
import numpy as np
import jax
import jax.numpy as jnp
import avblocks as av
from avblocks.core import diagnostics
from avblocks.utility import spatial as sp
from avblocks.utility.spatial.layout import layout

out = {"devices": len(jax.devices())}
N, K, R, D = 256, 6, 3.0, 4


def flock(seed=0):
    """A swirling, contracting flock: agents move between strips of space."""
    rng = np.random.default_rng(seed)
    p0 = rng.uniform(-25, 25, (N, 2))
    v0 = np.column_stack([-p0[:, 1], p0[:, 0]]) * 0.15 - p0 * 0.05
    d = av.Diagram()
    f = d.add(av.vehicles.DoubleIntegrator(p0, velocity0=v0), name="flock")
    # a plan with room for every agent: no re-plan (and its compile) here
    nb = d.add(av.environment.Neighbors(N, K, radius=R, input="position",
                                        method="cells", capacity=N), name="nb")
    law = d.add(av.controllers.Flocking(N, 2.0, r=R), name="law")
    d.connect(f.position, nb.position)
    d.connect(f.position, law.position)
    d.connect(f.velocity, law.velocity)
    d.connect(nb.neighbors, law.neighbors)
    d.connect(law.accel, f.accel)
    return d


kw = dict(dt=0.05, solver="euler", log=["flock.position", "nb.neighbors"], log_every=4,
          cache=False)
one = av.compile(flock(), 4.0, devices=1, **kw)
four = av.compile(flock(), 4.0, devices=4, shard="agents", **kw)
a, b = one(), four()
pa, pb = np.asarray(a["flock.position"]), np.asarray(b["flock.position"])
na, nbr = np.asarray(a["nb.neighbors"]), np.asarray(b["nb.neighbors"])
out["max_dp"] = float(np.abs(pa - pb).max())
out["neighbors_equal"] = bool(np.array_equal(na, nbr))
out["split"] = four._single.split
exe = four._run_exe[1]
out["exchanges"] = any(c in exe.as_text() for c in ("all-gather", "all-to-all",
                                                     "collective-permute", "all-reduce"))
# which device answered each agent's queries: its rank in the cell-sorted
# order (the search's own layout, plan of the run) over N / D
plan = four.plans["nb/0"]
blocks = []
for p in pa:
    rank = np.empty(N, int)
    rank[np.asarray(layout(plan, p).order)] = np.arange(N)
    blocks.append(rank // (N // D))
blocks = np.array(blocks)
out["crossed"] = int((blocks[1:] != blocks[:-1]).sum())       # agents that changed device
across = 0
border_equal = True
for t in range(len(pa)):
    nb_t = na[t]
    rows = [i for i in range(N) if any(j >= 0 and blocks[t][j] != blocks[t][i]
                                       for j in nb_t[i])]
    across += len(rows)
    border_equal &= bool(np.array_equal(na[t][rows], nbr[t][rows]))
out["rows_with_neighbours_on_other_devices"] = across
out["border_rows_equal"] = border_equal

# the searches alone, sharded against one device, on a cloud crowded at the
# strips' borders: a lattice whose rows of cells end on them, a random
# field and a stack of duplicates
jax.config.update("jax_enable_x64", True)
mesh = jax.sharding.Mesh(np.array(jax.devices()), ("d",))
rng = np.random.default_rng(1)
g = np.stack(np.meshgrid(np.arange(12), np.arange(12), indexing="ij"), -1).reshape(-1, 2)
p = np.concatenate([g * 1.5, rng.uniform(0, 18, (N - 144 - 24, 2)), np.full((24, 2), 9.0)])
cells = sp.plan_cells(p, R)


def q(p):
    i, dd, _ = sp.nearest(cells, p, R, K, None, jnp)
    w, wd, _ = sp.within(cells, p, R, None, jnp)
    c, _ = sp.candidates(cells, p, None, jnp)
    return i, dd, w, wd, c


def q4(p):
    with diagnostics.sharded(mesh, "d"):
        return q(p)


ps = jax.device_put(p, jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("d")))
r1 = [np.asarray(x) for x in jax.jit(q)(p)]
r4 = [np.asarray(x) for x in jax.jit(q4)(ps)]
out["searches_equal"] = {
    "nearest": bool(np.array_equal(r1[0], r4[0]) and np.array_equal(r1[1], r4[1])),
    "within": bool(np.array_equal(np.sort(r1[2], 1), np.sort(r4[2], 1))),
    "candidates": bool(np.array_equal(np.sort(r1[4], 1), np.sort(r4[4], 1)))}
order = np.asarray(layout(cells, p).order)
rank = np.empty(N, int)
rank[order] = np.arange(N)
blk = rank // (N // D)                # the device that answers each point's query
out["cloud_rows_on_borders"] = int(sum(any(blk[j] != blk[i] for j in r1[0][i] if j >= 0)
                                       for i in range(N)))

# an ensemble split over the devices by runs
x0 = {"flock.position": np.stack([np.random.default_rng(s).uniform(-25, 25, (N, 2))
                                  for s in range(4)])}
e1 = one.ensemble(seeds=range(4), x0=x0)
e4 = four.ensemble(seeds=range(4), x0=x0)
out["ensemble_max_dp"] = float(np.abs(np.asarray(e1["flock.position"])
                                      - np.asarray(e4["flock.position"])).max())
out["ensemble_split"] = any(k[0][0] == "ensemble" and k[0][-1][0] == "split"
                            for k in four.program._exe)
print("RESULT " + json.dumps(out))
'''


@pytest.mark.slow
def test_a_swarm_split_over_four_devices_equals_the_one_device_run(tmp_path):
    src = str(Path(av.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH",
                                                                            "")])}
    env.pop("JAX_NUM_CPU_DEVICES", None)
    p = subprocess.run([sys.executable, "-c", CHILD], env=env, cwd=tmp_path,
                       capture_output=True, text=True, timeout=1200)
    assert p.returncode == 0, p.stderr[-3000:]
    out = json.loads([x for x in p.stdout.splitlines() if x.startswith("RESULT ")][-1][7:])
    assert out["devices"] == 4
    assert out["split"] == 256                        # the agents were split...
    assert out["exchanges"]                           # ...and the devices exchange data
    assert out["max_dp"] < 1e-9
    assert out["neighbors_equal"]
    assert out["crossed"] > 0                         # agents moved between devices
    assert out["rows_with_neighbours_on_other_devices"] > 0      # the halo was read
    assert out["border_rows_equal"]
    assert out["searches_equal"] == {"nearest": True, "within": True, "candidates": True}
    assert out["cloud_rows_on_borders"] > 0          # rows whose neighbours another device owns
    assert out["ensemble_split"]
    assert out["ensemble_max_dp"] < 1e-9


def test_shard_agents_needs_the_agents_to_divide_over_the_devices():
    from avblocks.core.compiled import devices
    one = [object()] * 3
    with pytest.raises(av.ParameterError, match="divides 100 agents"):
        devices.check_shard("agents", one, 100)
    with pytest.raises(av.ParameterError, match="unknown shard"):
        devices.check_shard("space", one, 99)
    assert devices.check_shard("agents", one, 99) == "agents"
    assert devices.check_shard("agents", one[:1], 7) == "agents"


PROCESS = r'''
import os, sys
pid, port, out = int(sys.argv[1]), sys.argv[2], sys.argv[3]
os.environ["JAX_NUM_CPU_DEVICES"] = "2"
import jax
jax.config.update("jax_cpu_collectives_implementation", "gloo")
if pid >= 0:
    jax.distributed.initialize(coordinator_address=f"127.0.0.1:{port}", num_processes=2,
                               process_id=pid)
import numpy as np
import avblocks as av
N, K, R = 64, 4, 3.0
rng = np.random.default_rng(0)
p0 = rng.uniform(-12, 12, (N, 2))
v0 = np.column_stack([-p0[:, 1], p0[:, 0]]) * 0.15 - p0 * 0.05
d = av.Diagram()
f = d.add(av.vehicles.DoubleIntegrator(p0, velocity0=v0), name="flock")
nb = d.add(av.environment.Neighbors(N, K, radius=R, input="position", method="cells"),
           name="nb")
law = d.add(av.controllers.Flocking(N, 2.0, r=R), name="law")
d.connect(f.position, nb.position)
d.connect(f.position, law.position)
d.connect(f.velocity, law.velocity)
d.connect(nb.neighbors, law.neighbors)
d.connect(law.accel, f.accel)
kw = dict(dt=0.05, solver="euler", log=["flock.position", "nb.neighbors"], log_every=4,
          cache=False)
if pid >= 0:
    r = av.compile(d, 1.0, devices=jax.devices(), shard="agents", **kw)
else:
    r = av.compile(d, 1.0, devices=1, **kw)
res = r()
np.save(out, np.asarray(res["flock.position"]))
np.save(out + ".nb.npy", np.asarray(res["nb.neighbors"]))
print("devices", len(jax.devices()), "local", len(jax.local_devices()))
'''


@pytest.mark.slow
def test_a_swarm_split_over_two_processes_equals_one_device(tmp_path):
    """``jax.distributed`` on one machine: two processes of two CPU devices
    each (CPU collectives over gloo) run one sharded swarm over the four
    devices; each process gets the whole result, equal to one device's."""
    import socket

    import numpy as np
    src = str(Path(av.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH",
                                                                            "")])}
    env.pop("XLA_FLAGS", None)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = str(s.getsockname()[1])
    procs = [subprocess.Popen([sys.executable, "-c", PROCESS, str(i), port,
                               str(tmp_path / f"p{i}.npy")], env=env, cwd=tmp_path,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in (0, 1)]
    outs = [p.communicate(timeout=900) for p in procs]
    for p, (o, e) in zip(procs, outs):
        assert p.returncode == 0, e[-3000:]
        assert "devices 4 local 2" in o
    one = subprocess.run([sys.executable, "-c", PROCESS, "-1", port,
                          str(tmp_path / "one.npy")], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=900)
    assert one.returncode == 0, one.stderr[-3000:]
    want = np.load(tmp_path / "one.npy")
    for i in (0, 1):
        np.testing.assert_allclose(np.load(tmp_path / f"p{i}.npy"), want, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(np.load(tmp_path / f"p{i}.npy.nb.npy"),
                                      np.load(tmp_path / "one.npy.nb.npy"))
