"""Learning tasks as blocks: each task's observation, reward, done flag and
success measure computed with ``xp`` from the vehicles' outputs (so a plain
run logs the numbers an environment returns), and the scripted laws the
case studies run.

Pursuit: PursuitTask, Flee (the evader), Chase (the pursuers).
Spread: SpreadTask (+ :func:`assign_landmarks` for the scripted controller).
Navigation: NavigationTask, NavigationLaw.
Any task: TaskCommand (the scripted law's command, or a trained policy's).

The case studies that wire them (``avblocks run pursuit``, ``spread``,
``navigation``) and their environments (:func:`avblocks.rl.parallel_env`)
are in :mod:`avblocks.scenarios`.
"""

from .command import TaskCommand
from .navigation import REWARD, NavigationLaw, NavigationTask, obstacle_edges, scripted_law
from .pursuit import Chase, Flee, PursuitTask, flee_velocity
from .spread import SpreadTask, assign_landmarks

__all__ = [
    "PursuitTask", "Flee", "Chase", "flee_velocity",
    "SpreadTask", "assign_landmarks",
    "NavigationTask", "NavigationLaw", "REWARD", "scripted_law", "obstacle_edges",
    "TaskCommand",
]
