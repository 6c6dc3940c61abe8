"""benchmarks/rl_throughput.py: its hand-written navigation step (the
pure-JAX column) computes what the diagram's step computes, so the
throughput table compares the same work. No torch needed: without
``vmas`` the benchmark's VMAS columns say "not installed"."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("shapely")

from avblocks import rl  # noqa: E402

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "rl_throughput.py"


def _bench():
    spec = importlib.util.spec_from_file_location("rl_throughput", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _state(env, state):
    """(positions, goals, prev, hit) of the diagram's state."""
    cd = env.cd
    x_task = state.X[cd.index("task")]
    return (np.asarray(state.Y[cd.index("fleet")]["position"]),
            np.asarray(state.theta["goals.value"]), np.asarray(x_task["prev"]),
            np.asarray(x_task["hit"]))


def test_hand_written_step_equals_the_diagram_step():
    """NumPy engine (float64, shapely ray casts) against the benchmark's
    dense kernels run with NumPy: observation, reward, collision flags and
    positions agree over whole episodes of random actions, collisions
    included."""
    bench = _bench()
    step, _ = bench.navigation_task(4, np)
    env = rl.functional("navigation", backend="numpy")
    rng = np.random.default_rng(3)
    hits = 0
    for ep in range(4):
        state, _ = env.reset(np.array([ep, 11], dtype=np.uint32))
        p, g, prev, hit = _state(env, state)
        for _ in range(25):
            a = rng.uniform(-1.0, 1.0, (4, 2))
            a = np.clip(a, (-1.45 - p) / 0.1, (1.45 - p) / 0.1)   # stay in the arena
            state, obs, reward, _, info = env.step_env(state, a)
            p, obs_h, rew_h, prev, hit = step(p, g, prev, hit, a)
            p_d, _, _, hit_d = _state(env, state)
            np.testing.assert_allclose(p_d, p, atol=1e-12)
            np.testing.assert_allclose(obs, obs_h, atol=1e-5)        # obs are float32
            np.testing.assert_allclose(reward, rew_h, atol=1e-5)
            # the diagram's flag is updated at the step's start: with the
            # contact now, it is the episode's
            np.testing.assert_array_equal(hit_d | info["collision"], hit)
        hits += int(hit.sum())
    assert hits > 0                   # the collision terms were exercised


@pytest.mark.slow
def test_runs_without_torch(monkeypatch, capsys):
    """The quick table runs and names the missing VMAS columns."""
    import builtins
    real = builtins.__import__

    def no_vmas(name, *a, **k):
        if name.split(".")[0] in ("vmas", "torch"):
            raise ImportError(name)
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_vmas)
    rows = _bench().main(["--sizes", "1", "--steps", "3", "--repeats", "1", "--plot", ""])
    out = capsys.readouterr().out
    assert "not installed" in out
    assert rows[0]["avblocks"] > 0 and rows[0]["pure JAX"] > 0
