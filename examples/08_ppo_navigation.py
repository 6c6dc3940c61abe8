"""Learn the navigation task with PPO, jitted end to end, then run the policy as a block.

    python examples/08_ppo_navigation.py [UPDATES] [MINUTES]

``rl.functional("navigation")`` is the navigation scenario's diagram as pure
``reset``/``step`` functions on the compiled (JAX) engine. ``rl.ppo.train``
runs independent PPO with one shared actor and critic (every agent's
transition a sample): each update runs 128 episodes of 60 steps in
lockstep (one vmapped ``lax.scan``), then 4 epochs of 8 minibatches of
Adam, all in one jitted call; actor and critic are MLPs of two hidden
layers of 128 units. Observations are standardized by their
running mean and variance (``normalize_obs``; folded into the saved
weights). The learning rate (1e-3) decays linearly to zero over UPDATES
updates (default 2500) or MINUTES of wall time (default 10, compile
included), whichever ends first; training stops there. The wall time and
the CPU time of the process are printed (on a shared machine they differ).

The trained actor is evaluated on 100 new episodes (mean action, no
noise): success = the fraction of agents at their goal at the end of the
episode without having touched an obstacle, a wall or another agent. Its
weights go to ``navigation_ppo.npz``, a :class:`avblocks.controllers.Policy`
file: the navigation scenario runs it as its controller
(``avblocks run navigation --set controller=navigation_ppo.npz``), here on
the NumPy engine. Writes ppo_navigation.png: the learning curve (return and
success per update against wall time) and one evaluation episode.
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
from avblocks.rl import ppo  # noqa: E402
from avblocks.scenarios import navigation  # noqa: E402

updates = int(sys.argv[1]) if len(sys.argv) > 1 else 2500
minutes = float(sys.argv[2]) if len(sys.argv) > 2 else 10.0
small = bool(os.environ.get("AVBLOCKS_EXAMPLE_SMALL"))
cfg = ppo.Config(num_envs=128, minibatches=8, updates=updates, hidden=(128, 128),
                 normalize_obs=True, lr=1e-3, lam=0.9)
if small:
    cfg = ppo.Config(num_envs=8, updates=min(updates, 3), hidden=(32, 32), normalize_obs=True)

env = rl.functional("navigation")
print(env)
t0, c0 = time.perf_counter(), time.process_time()


def report(u, m):
    if u % 50 == 0:
        print(f"update {u:4d}  {time.perf_counter() - t0:6.1f} s  return {m['return']:6.2f}  "
              f"success {m['success']:.2f}", flush=True)


res = ppo.train(env, cfg, seed=0, time_budget_s=60 * minutes, callback=report)
wall, cpu = res.curve["wall_s"][-1], time.process_time() - c0
ev = ppo.evaluate(env, res.actor, episodes=10 if small else 100)
print(f"trained {len(res.curve['return'])} updates "
      f"({res.curve['env_steps'][-1] * env.n:,} agent-steps) in {wall:.0f} s "
      f"({cpu:.0f} s of CPU time); "
      f"evaluation over {10 if small else 100} episodes: success {ev['success']:.1%}, "
      f"collided {ev['collided']:.1%}, return {ev['return']:.2f}")

# the trained actor as a Policy block in the scenario's own diagram
path = save_policy("navigation_ppo.npz", res.actor, output="clip")
d, sim = navigation.make_diagram(controller=path, seed=3)
run = av.simulate(d, **sim)
line, _ = navigation.outcome(run, {})
print("as a Policy block (NumPy engine):", line)

fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.6))
t = np.asarray(res.curve["wall_s"])
a.plot(t, res.curve["return"], color="tab:blue", lw=1.2)
a.set_xlabel("wall time [s] (compile included)")
a.set_ylabel("episode return per agent", color="tab:blue")
a2 = a.twinx()
a2.plot(t, res.curve["success"], color="tab:green", lw=1.2)
a2.set_ylabel("success at episode end (training, noisy actions)", color="tab:green")
a2.set_ylim(0, 1)
a.set_title(f"PPO on navigation: eval success {ev['success']:.0%} "
            f"(100 episodes, mean action)", fontsize=10)
p = np.asarray(run["fleet.position"])
g = np.asarray(run["goals.y"])[0]
from matplotlib.patches import Rectangle  # noqa: E402

for cx, cy, w, h in navigation.OBSTACLES:
    b.add_patch(Rectangle((cx - w / 2, cy - h / 2), w, h, color="0.6"))
for i in range(p.shape[1]):
    ln, = b.plot(p[:, i, 0], p[:, i, 1], lw=1.5)
    b.plot(*g[i], "x", color=ln.get_color(), ms=9, mew=2)
    b.plot(*p[0, i], "o", color=ln.get_color(), ms=4)
b.set_xlim(-1.55, 1.55)
b.set_ylim(-1.55, 1.55)
b.set_aspect("equal")
b.set_title(line, fontsize=9)
fig.tight_layout()
fig.savefig("ppo_navigation.png", dpi=110)
print("wrote ppo_navigation.png, navigation_ppo.npz")
