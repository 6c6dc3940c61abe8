"""The compiled (JAX) backend against the NumPy engine, an analytic solution
and central finite differences: same results, no recompilation for new
values, ensembles, gradients, errors naming untraceable blocks."""

import os
import subprocess
import sys

import numpy as np
import pytest

import avblocks as av
from avblocks.core.errors import CompileError, ParameterError, SimulationError

if os.environ.get("CI"):
    import jax  # in CI the jax extra is installed: never skip
else:
    jax = pytest.importorskip("jax")
jnp = jax.numpy
pytestmark = pytest.mark.jax


class GoToGoal(av.Block):
    """Test-local unicycle go-to-goal law with declared parameters ``k``
    (gain, per agent) and ``d`` (look-ahead), written with ``xp`` only."""

    def __init__(self, goal, k=1.0, d=0.2):
        super().__init__()
        goal = np.asarray(goal, float)
        n = len(goal)
        self.goal = goal
        self.declare_parameter("k", k, (n,), bounds=(0, None))
        self.declare_parameter("d", d, (), bounds=(1e-3, None))
        self.declare_input("pose", (n, 3))
        self.declare_output("cmd", (n, 2))

    def output(self, t, x, u, xp):
        p = u["pose"]
        c, s = xp.cos(p[:, 2]), xp.sin(p[:, 2])
        ex = self.goal[:, 0] - p[:, 0] - self.d * c
        ey = self.goal[:, 1] - p[:, 1] - self.d * s
        wx, wy = self.k * ex, self.k * ey
        return {"cmd": xp.stack([c * wx + s * wy, (c * wy - s * wx) / self.d], axis=-1)}


def goto(n=4, seed=0):
    rng = np.random.default_rng(seed)
    p0 = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    d = av.Diagram()
    fleet = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
    law = d.add(GoToGoal(rng.uniform(-3, 3, (n, 2)), k=0.7, d=0.3), name="law")
    d.connect(fleet.pose, law.pose)
    d.connect(law.cmd, fleet.cmd)
    return d, p0


def waypoints(n=6, seed=0):
    rng = np.random.default_rng(seed)
    p0 = av.utility.random_poses(n, area=(20, 20), seed=seed)
    wps = [rng.uniform(0, 20, (k, 2)) for k in rng.integers(1, 4, n)]
    d = av.Diagram()
    fleet = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
    drive = d.add(av.controllers.PointToPoint(wps, d=0.1, gain=1.0, v_max=2.0, radius=0.2),
                  name="drive")
    d.connect(fleet.pose, drive.pose)
    d.connect(drive.cmd, fleet.cmd)
    return d


def ramp(k=2.0):
    """c = 1 -> Gain(k) -> Integrator: y(t) = k t exactly."""
    d = av.Diagram()
    c = d.add(av.blocks.Constant([[1.0, -0.5]]), name="c")
    g = d.add(av.blocks.Gain(k), name="g")
    i = d.add(av.blocks.Integrator([[0.0, 0.0]]), name="i")
    d.connect(c.y, g.u)
    d.connect(g.y, i.u)
    return d


# ------------------------------------------------------------ same results
@pytest.mark.parametrize("solver,log_every", [("rk4", 7), ("euler", 1)])
def test_matches_numpy_with_log_every_and_final_state(solver, log_every):
    ref = av.simulate(waypoints(), 12.0, dt=0.01, solver=solver, log_every=log_every,
                      log=["fleet.pose", "drive.cmd", "drive.done"])
    got = av.simulate(waypoints(), 12.0, dt=0.01, solver=solver, log_every=log_every,
                      log=["fleet.pose", "drive.cmd", "drive.done"], backend="jax")
    assert got.meta["backend"] == "jax" and got.meta["dtype"] == "float64"
    np.testing.assert_array_equal(got.t, ref.t)
    assert got["fleet.pose"].shape == ref["fleet.pose"].shape == (1200 // log_every + 1, 6, 3)
    assert np.max(np.abs(got["fleet.pose"] - ref["fleet.pose"])) < 1e-9
    assert np.max(np.abs(got["drive.cmd"] - ref["drive.cmd"])) < 1e-9
    np.testing.assert_array_equal(got["drive.done"], ref["drive.done"])
    assert ref["drive.done"][-1].any()          # discrete states did change
    # the final state is after all 1200 steps, also when log_every leaves a tail
    assert set(got.final_state) == set(ref.final_state)
    for k, v in ref.final_state.items():
        assert np.max(np.abs(np.asarray(got.final_state[k], float) - v)) < 1e-9, k


def test_multirate_blocks_match_numpy():
    def build():
        d = av.Diagram()
        src = d.add(av.blocks.Sine(amplitude=np.tile([1.0, 0.8], (5, 1)), frequency=0.7),
                    name="src")
        z = d.add(av.blocks.ZeroOrderHold(0.1, offset=0.05), name="zoh")
        dl = d.add(av.blocks.UnitDelay(np.zeros((5, 2)), period=0.2), name="delay")
        fleet = d.add(av.vehicles.Unicycle(pose0=av.utility.random_poses(
            5, area=(10, 10), seed=3)), name="fleet")
        d.connect(src.y, z.u)
        d.connect(z.y, dl.u)
        d.connect(dl.y, fleet.cmd)
        return d
    kw = dict(t_final=4.0, dt=0.01, log=["fleet.pose", "zoh.y", "delay.y"], log_every=3)
    ref = av.simulate(build(), **kw)
    got = av.simulate(build(), backend="jax", **kw)
    for k in kw["log"]:
        assert np.max(np.abs(got[k] - ref[k])) < 1e-9, k
    assert np.ptp(ref["delay.y"][:, :, 1]) > 0.5       # the held signal moves


def test_random_blocks_repeat_from_their_seed():
    # random blocks draw from the counter-based stream of core.rng: the same
    # seed gives the same run, and the same run as the NumPy engine
    def build():
        d = av.Diagram()
        rw = d.add(av.controllers.RandomWalk(4, interval=("exponential", 0.3)), name="rw")
        fleet = d.add(av.vehicles.Unicycle(pose0=np.zeros((4, 3))), name="fleet")
        d.connect(fleet.pose, rw.pose)
        d.connect(rw.cmd, fleet.cmd)
        return d
    kw = dict(t_final=2.0, dt=0.02, log=["fleet.pose"], backend="jax")
    a = av.simulate(build(), seed=1, **kw)["fleet.pose"]
    b = av.simulate(build(), seed=1, **kw)["fleet.pose"]
    c = av.simulate(build(), seed=2, **kw)["fleet.pose"]
    np.testing.assert_array_equal(a, b)
    assert np.max(np.abs(a - c)) > 0.1
    ref = av.simulate(build(), seed=1, **{**kw, "backend": "numpy"})["fleet.pose"]
    assert np.max(np.abs(a - ref)) < 1e-9


def test_analytic_ramp_and_params_argument():
    res = av.simulate(ramp(), 1.0, dt=0.1, log=["i.y"], params={"g.k": 3.0}, backend="jax")
    np.testing.assert_allclose(res["i.y"][:, 0, 0], 3.0 * res.t, atol=1e-12)
    np.testing.assert_allclose(res["i.y"][:, 0, 1], -1.5 * res.t, atol=1e-12)
    assert res.meta["params"] == {"g.k": 3.0}


# ---------------------------------------------------- compile once, run many
def test_second_simulate_with_other_values_does_not_recompile():
    from avblocks.core.compiled import cache_info
    d, p0 = goto()
    kw = dict(t_final=3.0, dt=0.01, solver="euler", log=["fleet.pose"], log_every=5)
    av.simulate(d, backend="jax", **kw)
    before = cache_info()["traces"]
    d2, _ = goto()                          # a new diagram object, same structure
    p1 = p0 + 0.5
    got = av.simulate(d2, backend="jax", params={"law.k": [0.3, 0.4, 0.5, 0.6]},
                      x0={"fleet.pose": p1}, seed=4, **kw)
    assert cache_info()["traces"] == before          # nothing traced or compiled
    ref = av.simulate(goto()[0], params={"law.k": [0.3, 0.4, 0.5, 0.6]},
                      x0={"fleet.pose": p1}, **kw)
    assert np.max(np.abs(got["fleet.pose"] - ref["fleet.pose"])) < 1e-9
    # a structural change (another goal table) compiles anew
    d3, _ = goto(seed=1)
    av.simulate(d3, backend="jax", **kw)
    assert cache_info()["traces"] == before + 1


def test_runner_calls_never_retrace_and_match_numpy():
    d, p0 = goto()
    runner = av.compile(d, 2.0, dt=0.01, log=["fleet.pose", "law.cmd"], log_every=4)
    r1 = runner()
    n = runner.compilations
    for gain, shift, seed in [(0.2, 0.0, 1), (1.5, 0.3, 2)]:
        res = runner(params={"law.k": gain, "law.d": 0.25}, x0={"fleet.pose": p0 + shift},
                     seed=seed)
        ref = av.simulate(goto()[0], 2.0, dt=0.01, log=["fleet.pose", "law.cmd"],
                          log_every=4, params={"law.k": gain, "law.d": 0.25},
                          x0={"fleet.pose": p0 + shift})
        assert np.max(np.abs(res["fleet.pose"] - ref["fleet.pose"])) < 1e-9
        assert res.meta["compile_time"] == 0.0
    assert runner.compilations == n
    assert r1.meta["steps"] == 200 and r1["law.cmd"].shape == (51, 4, 2)
    # the blocks keep their own values
    assert float(d.build().get_param("law.d")) == 0.3


def test_bad_values_are_refused_before_running():
    runner = av.compile(ramp(), 1.0, dt=0.1, log=["i.y"])
    with pytest.raises(ParameterError, match="no such numeric parameter"):
        runner(params={"g.gain": 1.0})
    with pytest.raises(ParameterError, match="wrong shape"):
        runner(x0={"i.x": np.zeros((3, 2))})
    with pytest.raises(ParameterError, match="real-time pacing"):
        av.simulate(ramp(), 1.0, dt=0.1, backend="jax", realtime=1.0)
    with pytest.raises(CompileError, match="fixed-step"):
        av.simulate(ramp(), 1.0, dt=0.1, solver="RK45", backend="jax")
    with pytest.raises(ParameterError, match="unknown backend"):
        av.simulate(ramp(), 1.0, dt=0.1, backend="torch")
    with pytest.raises(ParameterError, match="unknown keyword"):
        av.simulate(ramp(), 1.0, dt=0.1, dtype="float32")


# ------------------------------------------------ what cannot be compiled
class UsesNumPy(av.Block):
    def __init__(self, n):
        super().__init__()
        self.declare_input("pose", (n, 3))
        self.declare_output("cmd", (n, 2))

    def output(self, t, x, u, xp):
        p = np.asarray(u["pose"])               # forces a concrete array
        return {"cmd": np.column_stack([np.ones(len(p)), -p[:, 2]])}


class Flagged(UsesNumPy):
    traceable = False


@pytest.mark.parametrize("cls,match", [(UsesNumPy, "cannot be traced"),
                                       (Flagged, "traceable = False")])
def test_untraceable_block_is_named_at_compile_time(cls, match):
    d = av.Diagram()
    fleet = d.add(av.vehicles.Unicycle(pose0=np.zeros((3, 3))), name="fleet")
    ctl = d.add(cls(3), name="numpy_ctl")
    d.connect(fleet.pose, ctl.pose)
    d.connect(ctl.cmd, fleet.cmd)
    with pytest.raises(CompileError, match=match) as e:
        av.compile(d, 1.0, dt=0.1)(seed=0)
    assert e.value.block == "numpy_ctl" and "backend='numpy'" in str(e.value)
    av.simulate(d, 1.0, dt=0.1)                   # the NumPy engine runs it


def test_neighbors_block_compiles():
    # Neighbors traces since issue 21 (utility.spatial cell list)
    d = av.Diagram()
    pts = av.utility.random_positions(4, area=(5, 5), seed=1)
    fleet = d.add(av.vehicles.SingleIntegrator(pts), name="fleet")
    nb = d.add(av.environment.Neighbors(4, 2, radius=2.0, input="position"), name="nb")
    zero = d.add(av.blocks.Constant(np.zeros((4, 2))), name="zero")
    d.connect(fleet.position, nb.position)
    d.connect(zero.y, fleet.velocity)
    a = av.simulate(d, 1.0, dt=0.1, log=["nb.neighbors"])
    b = av.simulate(d, 1.0, dt=0.1, backend="jax", log=["nb.neighbors"])
    np.testing.assert_array_equal(a["nb.neighbors"], b["nb.neighbors"])


def test_nan_is_reported_with_the_results():
    # y = k t with k = 1e308 overflows to inf once t > 1.797...
    with pytest.raises(SimulationError, match="NaN or infinite") as e:
        av.simulate(ramp(1e308), 3.0, dt=0.1, log=["i.y"], backend="jax")
    assert e.value.block == "i" and e.value.port == "y"
    assert abs(e.value.time - 1.8) < 1e-9
    assert e.value.results["i.y"].shape == (31, 1, 2)     # nothing lost


# ------------------------------------------------------------- ensembles
def test_ensemble_seeds_params_x0_and_chunks():
    def build():
        d = av.Diagram()
        rw = d.add(av.controllers.RandomWalk(3, interval=("exponential", 0.3)), name="rw")
        fleet = d.add(av.vehicles.Unicycle(pose0=np.zeros((3, 3))), name="fleet")
        g = d.add(av.blocks.Gain(1.0), name="g")
        d.connect(fleet.pose, rw.pose)
        d.connect(rw.cmd, g.u)
        d.connect(g.y, fleet.cmd)
        return d
    runner = av.compile(build(), 1.0, dt=0.02, log=["fleet.pose"], log_every=5)
    R = 5
    gains = np.linspace(0.5, 1.5, R)
    p0 = np.zeros((R, 3, 3))
    p0[:, :, 0] = np.arange(R)[:, None]
    ens = runner.ensemble(seeds=range(10, 10 + R), params={"g.k": gains},
                          x0={"fleet.pose": p0})
    assert ens.runs == R and ens["fleet.pose"].shape == (R, 11, 3, 3)
    assert ens.final_state["fleet.pose"].shape == (R, 3, 3)
    for r in (0, 3):
        one = runner(seed=10 + r, params={"g.k": gains[r]}, x0={"fleet.pose": p0[r]})
        assert np.max(np.abs(ens["fleet.pose"][r] - one["fleet.pose"])) < 1e-12
        np.testing.assert_array_equal(ens.run(r)["fleet.pose"], ens["fleet.pose"][r])
    # chunked (2 runs per call, last chunk padded) gives the same numbers
    per_run = 11 * 3 * 3 * 8
    small = runner.ensemble(seeds=range(10, 10 + R), params={"g.k": gains},
                            x0={"fleet.pose": p0}, max_log_bytes=2 * per_run)
    assert small.meta["chunks"] == 3
    np.testing.assert_array_equal(small["fleet.pose"], ens["fleet.pose"])
    # the same by the chunk argument, which overrides the policy
    for chunk, calls in ((1, 5), (2, 3), (5, 1)):
        other = runner.ensemble(seeds=range(10, 10 + R), params={"g.k": gains},
                                x0={"fleet.pose": p0}, chunk=chunk)
        assert (other.meta["chunk_size"], other.meta["chunks"]) == (chunk, calls)
        np.testing.assert_array_equal(other["fleet.pose"], ens["fleet.pose"])
        np.testing.assert_array_equal(other.final_state["fleet.pose"],
                                      ens.final_state["fleet.pose"])
    with pytest.raises(av.ParameterError) as e:
        runner.ensemble(seeds=range(3), chunk=0)
    assert e.value.param == "chunk"
    ds = ens.to_xarray()
    assert ds["fleet.pose"].dims[:2] == ("run", "time")
    assert list(ds["seed"].values) == list(range(10, 10 + R))


def test_ensemble_results_save_and_load(tmp_path):
    runner = av.compile(ramp(), 1.0, dt=0.1, log=["i.y"])
    ens = runner.ensemble(params={"g.k": [1.0, 2.0, 3.0]}, x0={"i.x": [[[1.0, 0.0]]] * 3})
    # y = x0 + k t, against the closed form
    np.testing.assert_allclose(ens["i.y"][:, :, 0, 0],
                               1.0 + np.outer([1.0, 2.0, 3.0], ens.t), atol=1e-12)
    back = av.Results.load(ens.save(tmp_path / "ens.nc"))
    assert back.runs == 3
    np.testing.assert_array_equal(back["i.y"], ens["i.y"])


# ------------------------------------------------------------ gradients
def _fd(fun, x, h):
    x = np.asarray(x, float)
    g = np.zeros_like(x)
    for j in np.ndindex(x.shape):
        e = np.zeros_like(x)
        e[j] = h
        g[j] = (fun(x + e) - fun(x - e)) / (2 * h)
    return g


def test_gradients_match_central_differences_of_the_numpy_engine():
    d, p0 = goto(n=3)
    goal = d.build().blocks[d.build().index("law")].goal
    kw = dict(t_final=1.0, dt=0.01, solver="rk4", log=["fleet.pose"], log_every=10)

    def cost_np(res):
        P = res["fleet.pose"]
        return float(np.sum((P[-1, :, :2] - goal) ** 2) + 0.1 * np.sum(P[:, :, 2] ** 2))

    def cost(res):
        P = res["fleet.pose"]
        return jnp.sum((P[-1, :, :2] - goal) ** 2) + 0.1 * jnp.sum(P[:, :, 2] ** 2)

    k0, d0 = np.array([0.7, 0.4, 1.1]), 0.3
    base = {"law.k": k0, "law.d": d0}
    val, g = av.grad(cost, d, ["law.k", "law.d", "fleet.pose@x0"], params=base,
                     return_value=True, **kw)
    assert abs(val - cost_np(av.simulate(goto(n=3)[0], params=base, **kw))) < 1e-9

    def f(k=k0, dd=d0, pose=p0):
        return cost_np(av.simulate(goto(n=3)[0], params={"law.k": k, "law.d": dd},
                                   x0={"fleet.pose": pose}, **kw))
    fd = {"law.k": _fd(lambda k: f(k=k), k0, 1e-5),
          "law.d": _fd(lambda dd: f(dd=dd), d0, 1e-6),
          "fleet.pose@x0": _fd(lambda p: f(pose=p), p0, 1e-5)}
    for name, ref in fd.items():
        assert g[name].shape == np.shape(ref)
        rel = np.max(np.abs(g[name] - ref)) / np.max(np.abs(ref))
        assert rel < 1e-5, (name, rel, g[name], ref)


def test_gradient_of_gain_analytic_and_no_recompile():
    runner = av.compile(ramp(), 1.0, dt=0.1, log=["i.y"])

    def cost(res):
        return jnp.sum(res["i.y"][-1] ** 2)         # (k^2 + k^2/4) at t = 1
    for k in (2.0, -1.0):
        val, g = runner.value_and_grad(cost, ["g.k"], params={"g.k": k})
        assert abs(val - 1.25 * k * k) < 1e-12
        assert abs(float(g["g.k"]) - 2.5 * k) < 1e-12
    n = runner.compilations
    runner.grad(cost, ["g.k"], params={"g.k": 0.5})
    assert runner.compilations == n


# -------------------------------------------------------------- float32
def test_float32_runs_and_drifts_little_on_a_closed_loop():
    d, _ = goto()
    kw = dict(t_final=5.0, dt=0.01, solver="euler", log=["fleet.pose"])
    r64 = av.simulate(d, backend="jax", **kw)
    r32 = av.simulate(d, backend="jax", dtype="float32", **kw)
    assert r32["fleet.pose"].dtype == np.float32 and r32.meta["dtype"] == "float32"
    err = np.max(np.abs(r32["fleet.pose"].astype(float) - r64["fleet.pose"]))
    assert 0 < err < 1e-4                     # rounding differs, but stays small


# ------------------------------------------------------------- the rest
def test_persistent_cache_writes_files(tmp_path):
    code = f"""
import numpy as np, avblocks as av
from avblocks.core.compiled import enable_persistent_cache
enable_persistent_cache({str(tmp_path)!r})
d = av.Diagram()
c = d.add(av.blocks.Constant([[1.0]]), name="c")
i = d.add(av.blocks.Integrator([[0.0]]), name="i")
d.connect(c.y, i.u)
print(float(av.simulate(d, 1.0, dt=0.1, log=["i.y"], backend="jax")["i.y"][-1, 0, 0]))
"""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(__import__("pathlib").Path(av.__file__).parents[1])] + sys.path))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    assert abs(float(out.stdout.strip().splitlines()[-1]) - 1.0) < 1e-12
    assert any(tmp_path.iterdir())


def test_simulate_jax_compat_and_numpy_final_state():
    from avblocks.core.jax_backend import simulate_jax
    res = simulate_jax(ramp(), 1.0, dt=0.1, log=["i.y"])
    np.testing.assert_allclose(res["i.y"][-1, 0], [2.0, -1.0], atol=1e-12)
    ref = av.simulate(ramp(), 1.0, dt=0.1, log=["i.y"])
    np.testing.assert_allclose(ref.final_state["i.x"], [[2.0, -1.0]], atol=1e-12)


def test_leader_follower_gain_gradients_match_finite_differences():
    n = 3
    leader, l_ref, a_ref = av.controllers.formation("wedge", n, 1.5)

    def build():
        p0 = np.column_stack([-np.arange(n) * 1.2, np.linspace(-1, 1.5, n),
                              np.linspace(0.2, -0.3, n)])
        d = av.Diagram()
        f = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
        c = d.add(av.blocks.Constant(np.tile([0.8, 0.1], (n, 1))), name="lead")
        lf = d.add(av.controllers.LeaderFollower(leader, l_ref=l_ref, alpha_ref=a_ref,
                                                 d=0.2, k_l=0.8, k_alpha=0.6), name="lf")
        d.connect(f.pose, lf.pose)
        d.connect(c.y, lf.cmd_in)
        d.connect(lf.cmd, f.cmd)
        return d
    kw = dict(t_final=2.0, dt=0.01, solver="euler", log=["lf.error"], log_every=10)

    def cost(res):
        return jnp.sum(res["lf.error"] ** 2)

    base = {"lf.k_l": np.full(n, 0.8), "lf.k_alpha": np.full(n, 0.6)}
    g = av.grad(cost, build(), ["lf.k_l", "lf.k_alpha"], params=base, **kw)

    def f(path, v):
        res = av.simulate(build(), params={**base, path: v}, **kw)
        return float(np.sum(res["lf.error"] ** 2))
    for path in base:
        fd = _fd(lambda v, path=path: f(path, v), base[path], 1e-5)
        followers = leader >= 0
        assert np.all(g[path][~followers] == 0)        # the root's gains do nothing
        rel = np.max(np.abs(g[path] - fd)) / np.max(np.abs(fd))
        assert rel < 1e-5, (path, rel, g[path], fd)
        assert np.all(g[path][followers] < 0)          # larger gains: smaller errors


def test_cli_backend_option(tmp_path, capsys):
    from avblocks.cli import main
    args = ["run", "waypoints", "--set", "agents=4", "--t-final", "3", "--quiet"]
    assert main(args + ["--out", str(tmp_path / "np")]) == 0
    assert main(args + ["--out", str(tmp_path / "jax"), "--backend", "jax"]) == 0
    a = av.Results.load(tmp_path / "np" / "results.nc")
    b = av.Results.load(tmp_path / "jax" / "results.nc")
    assert b.meta["backend"] == "jax" and b["fleet.pose"].shape == a["fleet.pose"].shape
    assert np.max(np.abs(a["fleet.pose"] - b["fleet.pose"])) < 1e-9
    capsys.readouterr()
    # a scenario with a NumPy-only block (every built-in case study compiles
    # now; the exact shapely collision test does not): one clear line, exit 2
    scen = tmp_path / "numpy_only.py"
    scen.write_text(
        "import numpy as np\nimport avblocks as av\n"
        "def make_diagram(agents=3, t_final=1.0, dt=0.1):\n"
        "    d = av.Diagram()\n"
        "    f = d.add(av.vehicles.Unicycle(pose0=np.zeros((agents, 3))), name='fleet')\n"
        "    c = d.add(av.blocks.Constant(np.ones((agents, 2))), name='go')\n"
        "    w = av.environment.World([av.environment.rectangle(2, -1, 3, 1)])\n"
        "    h = d.add(av.environment.Collision(w, agents, method='shapely'), name='hit')\n"
        "    d.connect(c.y, f.cmd)\n    d.connect(f.pose, h.pose)\n"
        "    return d, dict(t_final=t_final, dt=dt)\n")
    assert main(["run", str(scen), "--quiet", "--out", str(tmp_path / "np_only"),
                 "--backend", "jax"]) == 2
    err = capsys.readouterr().err
    assert "cannot be compiled" in err and "backend='numpy'" in err


def test_cached_program_never_traces_blocks_changed_since():
    d1, _ = goto(seed=7)
    kw = dict(t_final=1.0, dt=0.05, solver="euler", log=["fleet.pose"])
    r1 = av.compile(d1, **kw)
    r1()
    d1.build().blocks[d1.build().index("law")].goal += 5.0     # structural change to d1
    d2, _ = goto(seed=7)                        # the original structure, new objects
    r2 = av.compile(d2, **kw)
    assert r2.program is r1.program             # cache hit on the original key
    ens = r2.ensemble(runs=2)                   # a new trace: must use d2's blocks
    ref = av.simulate(goto(seed=7)[0], **kw)
    assert np.max(np.abs(ens["fleet.pose"][1] - ref["fleet.pose"])) < 1e-9


def test_compile_refuses_a_run_that_is_not_whole_steps():
    """compile() makes the same checks as every engine: a t_final that is
    not t0 + k dt is refused with the two nearest valid end times (it was
    rounded silently before)."""
    d, _ = goto(seed=1)
    with pytest.raises(av.ParameterError, match="whole number of major steps") as e:
        av.compile(d, 1.005, dt=0.01)
    assert "1 or 1.01" in str(e.value)
    with pytest.raises(av.ParameterError, match="finite number"):
        av.compile(d, float("nan"), dt=0.01)


def test_structure_key_sees_every_structural_change_and_ignores_values():
    """The compile-cache key is worked out on every simulate(backend="jax")
    call, with records that can never change (frozen ports) fingerprinted
    once: a port of another shape, a frozen record holding a list that is
    changed in place, and a changed non-parameter array each give a new key;
    parameter values and a parameter's bounds (validation only) do not."""
    import dataclasses

    from avblocks.core.compiled.structure import block_fingerprint, fingerprint

    def key(b):
        return block_fingerprint(b)

    a, b = GoToGoal(np.zeros((3, 2))), GoToGoal(np.zeros((3, 2)))
    assert key(a) == key(b)
    b.set_parameter("k", [2.0, 3.0, 4.0])
    b._params["k"].bounds = (1.0, None)
    assert key(a) == key(b)                         # values and bounds are data
    b.goal[0, 0] = 1.0                              # in place, not a parameter
    assert key(a) != key(b)
    c = GoToGoal(np.zeros((4, 2)))                  # ports of another shape
    assert key(a) != key(c)

    @dataclasses.dataclass(frozen=True)
    class Rec:
        items: list
    r = Rec([1, 2])
    before = fingerprint(r)
    r.items.append(3)                               # frozen, but not plain
    assert fingerprint(r) != before
    p = av.Port("y", (2, 3))
    assert fingerprint(p) == fingerprint(av.Port("y", (2, 3)))
    assert fingerprint(p) != fingerprint(av.Port("y", (2, 4)))
