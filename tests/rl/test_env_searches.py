"""An environment's neighbour searches on the JAX engine: planned as a
compiled run plans them, exact while the plan holds, and a plan too small
for what an episode met is reported (SimulationError), never silent. What
the searches needed is carried in the state (no host call per step)."""

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnasium")

from avblocks import Diagram, rl  # noqa: E402
from avblocks.blocks import Action  # noqa: E402
from avblocks.core.errors import SimulationError  # noqa: E402
from avblocks.environment import Neighbors  # noqa: E402
from avblocks.vehicles import SingleIntegrator  # noqa: E402

N, K, R = 100, 4, 1.5


def lattice():
    g = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0)), -1).reshape(-1, 2)
    return g + np.random.default_rng(0).uniform(-0.1, 0.1, g.shape)


def task(**kw):
    d = Diagram("crowd")
    act = d.add(Action(N, 2, low=-50.0, high=50.0), name="act")
    fleet = d.add(SingleIntegrator(lattice()), name="fleet")
    nb = d.add(Neighbors(N, K, radius=R, input="position", method="cells"), name="nb")
    d.connect(act.action, fleet.velocity)
    d.connect(fleet.position, nb.position)
    return rl.make_task(d, act="act", observe=["nb.neighbors", "fleet.position"],
                        reward=lambda sig, a, xp: xp.zeros(N), dt=0.1, max_steps=100,
                        solver="euler", **kw)


def brute(p):
    """Independent truth: all pairs, the K nearest within R by (distance, index)."""
    d = np.sqrt(((p[None] - p[:, None]) ** 2).sum(-1))
    ok = (d <= R) & ~np.eye(len(p), dtype=bool)
    dm = np.where(ok, d, np.inf)
    j = np.broadcast_to(np.arange(len(p)), dm.shape)
    o = np.lexsort((j, dm), axis=-1)[:, :K]
    return np.take_along_axis(np.where(ok, j, -1), o, 1)


def most_candidates(p, reach=R, split=2):
    """Independent count: the most points in the 5 x 5 cells (edge reach /
    split) around one point's own cell."""
    c = np.floor(p / (reach / split)).astype(np.int64)
    return int(np.max(np.all(np.abs(c[None] - c[:, None]) <= split, -1).sum(1)))


def toward_centre(p, frac):
    return (frac * (np.array([4.5, 4.5]) - p) / 0.1).astype(np.float32)


def observed(obs):
    o = np.asarray(obs)
    return o[:, :K].astype(int), o[:, K:]


def test_searches_are_planned_exact_and_tallied_without_host_calls():
    env = rl.functional(task())
    plan = env.cd.blocks[env.cd.index("nb")].search.cells
    assert plan is not None and plan.capacity >= most_candidates(lattice())
    step = jax.jit(env.step_env)
    state, obs = env.reset(np.array([1, 2], np.uint32))
    seen = [observed(obs)[1].astype(np.float64)]
    for _ in range(3):                    # a little contraction: the plan holds
        a = toward_centre(np.asarray(state.X[env.cd.index("fleet")]["position"]), 0.05)
        state, obs, *_ = step(state, a)
        assert env.overflows(state) == []
        idx, pos = observed(obs)
        np.testing.assert_array_equal(idx, brute(pos.astype(np.float64)))
        seen.append(pos.astype(np.float64))
    # the running maximum over the evaluations, counted independently
    need = np.asarray(state.needs)[env._rows[("nb", 0)]]
    assert int(need[0]) == max(most_candidates(p) for p in seen) > most_candidates(seen[0])
    jaxpr = str(jax.make_jaxpr(env.step_env)(state, a))
    assert "callback" not in jaxpr


def test_a_plan_too_small_is_reported_by_check_wrappers_and_rollout():
    env = rl.functional(task())
    plan = env.cd.blocks[env.cd.index("nb")].search.cells
    step = jax.jit(env.step_env)
    state, _ = env.reset(np.array([3, 4], np.uint32))
    a = toward_centre(lattice(), 0.999)             # everyone to the centre at once
    state, obs, *_ = step(state, a)
    _, pos = observed(obs)
    want = most_candidates(pos.astype(np.float64))
    assert want == N > plan.capacity
    need = np.asarray(state.needs)[env._rows[("nb", 0)]]
    assert int(need[0]) == want                     # counted exactly, in the state
    over = env.overflows(state)
    assert [o[0] for o in over] == ["nb"] and "capacity" in over[0][3]
    with pytest.raises(SimulationError, match="capacity"):
        env.check(state)
    # the wrappers check after each step
    venv = rl.vector_env(task(), 2)
    venv.reset(seed=0)
    with pytest.raises(SimulationError, match="'nb'"):
        venv.step(np.stack([a.reshape(N, 2)] * 2))
    # and a rollout called outside a transformation
    with pytest.raises(SimulationError, match="capacity"):
        env.rollout(np.array([5, 6], np.uint32),
                    lambda th, o, k: jax.numpy.asarray(toward_centre(lattice(), 0.999)), 2)
