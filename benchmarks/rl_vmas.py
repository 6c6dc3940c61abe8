"""VMAS columns of ``rl_throughput.py`` (needs ``vmas`` and torch: extra ``rl-bench``).

Two VMAS set-ups of the navigation task (on CPU unless told), both stepped with
uniform random forces in ``[-1, 1]^2`` per agent:

- ``stock``: VMAS's own ``navigation`` scenario with our sizes: 4 agents
  of radius 0.1, spawned in ``[-1.5, 1.5]^2`` (``enforce_bounds``: the
  positions are clamped to the square), 12 lidar rays of range 1.0 that
  see the other agents only; no obstacles.
- ``obstacles``: the same scenario plus our three rectangles
  (``avblocks.scenarios.navigation.OBSTACLES``) as ``Box`` landmarks and
  the arena's border as four ``Line`` landmarks, all colliding and all
  seen by the lidar; starts and goals drawn outside the rectangles
  (clearance 0.25, like ours). The closest like-for-like of our task.

Only ``env.step`` is timed (observations, rewards, dones and infos of
every agent are computed by it); resets are not.
"""

from __future__ import annotations

import math

import torch
from vmas import make_env
from vmas.scenarios.navigation import Scenario as _Navigation
from vmas.simulator.core import Box, Landmark, Line
from vmas.simulator.utils import Color

HALF, RADIUS, RAYS, RANGE, CLEARANCE = 1.5, 0.1, 12, 1.0, 0.25

STOCK = {"n_agents": 4, "enforce_bounds": True, "world_spawning_x": HALF,
         "world_spawning_y": HALF, "agent_radius": RADIUS, "n_lidar_rays": RAYS,
         "lidar_range": RANGE}


class NavigationWithObstacles(_Navigation):
    """VMAS's navigation scenario with our rectangles and walls as landmarks."""

    def make_world(self, batch_dim, device, **kwargs):
        from avblocks.scenarios.navigation import OBSTACLES
        self.rects = [tuple(float(v) for v in o) for o in OBSTACLES]
        world = super().make_world(batch_dim, device, **kwargs)
        self.obstacles = []
        for i, (_cx, _cy, w, h) in enumerate(self.rects):
            box = Landmark(name=f"obstacle {i}", collide=True, movable=False,
                           shape=Box(length=w, width=h), color=Color.BLACK)
            world.add_landmark(box)
            self.obstacles.append(box)
        self.walls = []
        for i in range(4):
            wall = Landmark(name=f"wall {i}", collide=True, movable=False,
                            shape=Line(length=2 * HALF), color=Color.BLACK)
            world.add_landmark(wall)
            self.walls.append(wall)
        for agent in world.agents:                 # the lidar sees everything solid
            agent.sensors[0].entity_filter = lambda e: e.collide
        return world

    def _free(self, batch, occupied, tries=32):
        """(batch, 1, 2) positions outside the rectangles grown by the
        clearance, inside the arena less the clearance, and at least
        ``min_distance_between_entities`` from ``occupied``."""
        lim = HALF - CLEARANCE
        q = torch.empty((batch, tries, 2), device=self.world.device).uniform_(-lim, lim)
        ok = torch.ones((batch, tries), dtype=torch.bool, device=q.device)
        for cx, cy, w, h in self.rects:
            inside = ((q[..., 0] - cx).abs() < w / 2 + CLEARANCE) & \
                     ((q[..., 1] - cy).abs() < h / 2 + CLEARANCE)
            ok &= ~inside
        if occupied.shape[1]:
            ok &= torch.cdist(q, occupied).min(-1).values >= self.min_distance_between_entities
        pick = ok.float().argmax(-1)
        return q[torch.arange(batch, device=q.device), pick].unsqueeze(1)

    def reset_world_at(self, env_index=None):
        batch = self.world.batch_dim if env_index is None else 1
        dev = self.world.device
        occupied = torch.zeros((batch, 0, 2), device=dev)
        for agent in self.world.agents:
            pos = self._free(batch, occupied)
            occupied = torch.cat([occupied, pos], 1)
            agent.set_pos(pos.squeeze(1), batch_index=env_index)
        goals = torch.zeros((batch, 0, 2), device=dev)
        for agent in self.world.agents:
            pos = self._free(batch, goals)
            goals = torch.cat([goals, pos], 1)
            agent.goal.set_pos(pos.squeeze(1), batch_index=env_index)
            d = torch.linalg.vector_norm(agent.state.pos - agent.goal.state.pos, dim=-1)
            if env_index is None:
                agent.pos_shaping = d * self.pos_shaping_factor
            else:
                agent.pos_shaping[env_index] = d[env_index] * self.pos_shaping_factor

        def place(entity, xy, rot):
            xy = torch.tensor(xy, dtype=torch.float32, device=dev)
            rot = torch.tensor([rot], dtype=torch.float32, device=dev)
            if env_index is None:
                xy, rot = xy.expand(batch, 2), rot.expand(batch, 1)
            entity.set_pos(xy, batch_index=env_index)
            entity.set_rot(rot, batch_index=env_index)

        for box, (cx, cy, _w, _h) in zip(self.obstacles, self.rects):
            place(box, (cx, cy), 0.0)
        for wall, (xy, rot) in zip(self.walls, (((HALF, 0.0), math.pi / 2),
                                                ((-HALF, 0.0), math.pi / 2),
                                                ((0.0, HALF), 0.0), ((0.0, -HALF), 0.0))):
            place(wall, xy, rot)


def make(variant, num_envs, n=4, seed=0, device="cpu"):
    """A VMAS environment of ``num_envs`` copies, reset: ``variant``
    ``"stock"`` or ``"obstacles"`` (module docstring)."""
    kw = dict(STOCK, n_agents=n)
    if variant == "stock":
        scenario = "navigation"
    elif variant == "obstacles":
        scenario = NavigationWithObstacles()
        kw["enforce_bounds"] = False              # the walls bound the arena
    else:
        raise ValueError(f"VMAS variant: expected 'stock' or 'obstacles', found {variant!r}")
    env = make_env(scenario, num_envs=num_envs, device=device, continuous_actions=True,
                   seed=seed, **kw)
    env.reset()
    return env


def runner(variant, E, T, n=4, threads=1, device="cpu"):
    """``run()`` stepping ``T`` random actions on ``E`` copies with
    ``threads`` torch threads (set before each run) on ``device``."""
    env = make(variant, E, n, device=device)

    def run():
        torch.set_num_threads(threads)
        for _ in range(T):
            env.step([torch.rand(E, 2, device=device) * 2 - 1 for _ in range(n)])
        if device != "cpu":
            torch.cuda.synchronize()

    return run


def positions(env):
    """(E, n, 2) agent positions (for the checks)."""
    return torch.stack([a.state.pos for a in env.world.agents], 1)
