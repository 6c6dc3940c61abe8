"""Controllers: each a block with standard ports, its law a pure function.

Unicycles (``pose`` in, ``cmd`` = (v, omega) out): PointToPoint,
LeaderFollower, RandomWalk, HolonomicToUnicycle (+ OffAxisPoint).
Single integrators (``position`` in, ``velocity`` out): HolonomicPointToPoint,
Consensus, DisplacementFormation, CyclicPursuit, Coverage,
CollisionAvoidance; 3-D virtual structure: FormationReference (planned
positions and velocities) and ReferenceTracker (``velocity`` out).
Double integrators (``accel`` out): Flocking. Following a measured
target (alpha-beta filter + velocity law): TrackingController.
Discrete-event: Supervisor, AgentModes.
Learned: Policy (obs in, cmd out; mlp). Formation helpers: formation() etc.
"""

from .collision_avoidance import CollisionAvoidance, safety_filter
from .consensus import Consensus, consensus_law
from .coverage import Coverage, cell_moments, coverage_cost, lloyd_velocity, voronoi_cells
from .cyclic_pursuit import CyclicPursuit, cyclic_pursuit_law
from .displacement_formation import DisplacementFormation, displacement_formation_law
from .flocking import Flocking, bump, flocking_law, order_parameter, phi_alpha, sigma_norm
from .formations import formation, formation_offsets, leader_tree, references, virtual_grid
from .holonomic_point_to_point import HolonomicPointToPoint, holonomic_point_to_point_law
from .leader_follower import LeaderFollower, leader_follower_law, leader_follower_terms
from .offaxis import HolonomicToUnicycle, OffAxisPoint, holonomic_to_unicycle, off_axis_point
from .point_to_point import PointToPoint, point_to_point_law
from .policy import Policy, mlp, mlp_init, save_policy
from .random_walk import Distribution, RandomWalk, random_walk_cmd
from .supervisor import AgentModes, Supervisor
from .target_tracking import TrackingController, alpha_beta_step, follow_velocity
from .virtual_structure import (
    FormationReference,
    ReferenceTracker,
    reference_tracking_law,
    virtual_structure_reference,
)

__all__ = [
    "PointToPoint", "point_to_point_law",
    "HolonomicPointToPoint", "holonomic_point_to_point_law",
    "LeaderFollower", "leader_follower_law", "leader_follower_terms",
    "formation", "formation_offsets", "leader_tree", "references", "virtual_grid",
    "OffAxisPoint", "HolonomicToUnicycle", "off_axis_point", "holonomic_to_unicycle",
    "Consensus", "consensus_law", "DisplacementFormation", "displacement_formation_law",
    "CyclicPursuit", "cyclic_pursuit_law",
    "Coverage", "coverage_cost", "cell_moments", "lloyd_velocity", "voronoi_cells",
    "CollisionAvoidance", "safety_filter",
    "Supervisor", "AgentModes",
    "RandomWalk", "Distribution", "random_walk_cmd",
    "Flocking", "flocking_law", "sigma_norm", "bump", "phi_alpha", "order_parameter",
    "Policy", "mlp", "mlp_init", "save_policy",
    "FormationReference", "ReferenceTracker", "virtual_structure_reference",
    "reference_tracking_law",
    "TrackingController", "alpha_beta_step", "follow_velocity",
]
