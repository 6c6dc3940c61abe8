"""Learn the navigation task by analytic policy gradients: backpropagation through the run.

    python examples/09_apg_navigation.py [UPDATES] [MINUTES]

The same task and policy size as examples/08_ppo_navigation.py, trained
another way: the episode (vehicles, range rays, task block: the compiled
engine's traced step) is differentiated end to end with respect to the
policy's weights, and Adam descends the gradient of a smooth cost,
``rl.apg.train``. The policy is deterministic, ``a = tanh(MLP(obs))``.

The task's own reward has indicator terms (a collision costs a constant,
reaching the goal earns a constant) whose gradient is zero almost
everywhere, so the cost here is its smooth counterpart, written from the
observation (layout in the navigation scenario's docstring):

    cost_i(t) = |g_i - p_i|                                  (distance to go)
              + 20 * sum_rays relu(0.2 - range)^2            (keep off obstacles)
              + 20 * sum_others relu(0.3 - |p_j - p_i|)^2    (keep off agents)

Each update differentiates 64 episodes of 60 steps (the gradient cut into
windows of 20 steps). Training stops after UPDATES (default 3000) or
MINUTES (default 10, compile included). Evaluated like example 08 (100
episodes, success = at the goal at the end without any collision); writes
apg_navigation.png (cost, return and success per update) and
navigation_apg.npz (a Policy file, ``output="tanh"``).
"""

import os
import sys
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import avblocks as av  # noqa: E402
from avblocks import rl  # noqa: E402
from avblocks.controllers import save_policy  # noqa: E402
from avblocks.rl import apg, ppo  # noqa: E402
from avblocks.scenarios import navigation  # noqa: E402

updates = int(sys.argv[1]) if len(sys.argv) > 1 else 3000
minutes = float(sys.argv[2]) if len(sys.argv) > 2 else 10.0
small = bool(os.environ.get("AVBLOCKS_EXAMPLE_SMALL"))
cfg = apg.Config(num_envs=64, updates=updates, horizon=20, lr=1e-3)
if small:
    cfg = apg.Config(num_envs=8, updates=min(updates, 3), hidden=(32, 32), horizon=20)

env = rl.functional("navigation")
RAYS, MAX_RANGE = 12, 1.0


def smooth_cost(obs, reward, info, action, xp):
    to_go = xp.sqrt(xp.sum(obs[:, 0:2] ** 2, -1) + 1e-9)
    ranges = obs[:, 4:4 + RAYS] * MAX_RANGE
    others = obs[:, 4 + RAYS:].reshape(obs.shape[0], -1, 2)
    d_others = xp.sqrt(xp.sum(others ** 2, -1) + 1e-9)
    return (to_go + 20.0 * xp.sum(xp.maximum(0.2 - ranges, 0.0) ** 2, -1)
            + 20.0 * xp.sum(xp.maximum(0.3 - d_others, 0.0) ** 2, -1))


t0 = time.perf_counter()


def report(u, m):
    if u % 50 == 0:
        print(f"update {u:4d}  {time.perf_counter() - t0:6.1f} s  cost {m['cost']:.3f}  "
              f"return {m['return']:6.2f}  success {m['success']:.2f}", flush=True)


res = apg.train(env, cfg, seed=0, cost=smooth_cost, time_budget_s=60 * minutes,
                callback=report)
wall = res.curve["wall_s"][-1]
ev = ppo.evaluate(env, res.actor, episodes=10 if small else 100, output="tanh")
print(f"trained {len(res.curve['cost'])} updates "
      f"({res.curve['env_steps'][-1] * env.n:,} agent-steps) in {wall:.0f} s; "
      f"evaluation over {10 if small else 100} episodes: success {ev['success']:.1%}, "
      f"collided {ev['collided']:.1%}, return {ev['return']:.2f}")

path = save_policy("navigation_apg.npz", res.actor, output="tanh")
d, sim = navigation.make_diagram(controller=path, seed=3)
run = av.simulate(d, **sim)
line, _ = navigation.outcome(run, {})
print("as a Policy block (NumPy engine):", line)

fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.4))
t = np.asarray(res.curve["wall_s"])
a.plot(t, res.curve["cost"], color="tab:red", lw=1.2)
a.set_xlabel("wall time [s] (compile included)")
a.set_ylabel("smooth cost per agent-step", color="tab:red")
b.plot(t, res.curve["return"], color="tab:blue", lw=1.2)
b.set_xlabel("wall time [s] (compile included)")
b.set_ylabel("task return per agent", color="tab:blue")
b2 = b.twinx()
b2.plot(t, res.curve["success"], color="tab:green", lw=1.2)
b2.set_ylabel("success at episode end", color="tab:green")
b2.set_ylim(0, 1)
fig.suptitle(f"APG on navigation: eval success {ev['success']:.0%} (100 episodes)",
             fontsize=10)
fig.tight_layout()
fig.savefig("apg_navigation.png", dpi=110)
print("wrote apg_navigation.png, navigation_apg.npz")
