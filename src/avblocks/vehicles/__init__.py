"""Vehicle models: one block = N vehicles. Each family is a pure dynamics
function plus a block that wraps it.

===========================  ======================  ==================================
block                        input                   outputs
===========================  ======================  ==================================
Unicycle                     cmd (v, omega)          pose
Unicycle2                    wrench (f, tau)         pose, twist
DiffDrive                    wheels (left, right)    pose
Ackermann                    cmd (v, delta)          pose [, steer]
SingleIntegrator             velocity                position
DoubleIntegrator             accel | force           position, velocity
Quadrotor                    wrench | rotors         position, velocity, attitude,
                                                     rates, pose
QuadrotorVelocityControl     velocity + feedback     wrench | rotors
VelocityControlledQuadrotor  velocity                position, pose, attitude
Blimp                        thrust (f_x, f_z, tau)  position, velocity, pose,
                                                     body_velocity
===========================  ======================  ==================================
"""

from ._rotations import (
    quat_derivative,
    quat_from_euler,
    quat_mul,
    quat_normalize,
    quat_rotate,
    quat_to_rotmat,
    quat_yaw,
)
from .ackermann import Ackermann, ackermann_rhs
from .blimp import Blimp, blimp_rhs
from .diffdrive import DiffDrive, diffdrive_rhs, twist_to_wheels, wheels_to_twist
from .integrators import DoubleIntegrator, SingleIntegrator
from .quadrotor import (
    Quadrotor,
    mixer_matrix,
    quadrotor_rhs,
    rotors_to_wrench,
    wrench_to_rotors,
)
from .quadrotor_control import (
    QuadrotorVelocityControl,
    VelocityControlledQuadrotor,
    velocity_controlled_quadrotor,
)
from .unicycle import Unicycle, unicycle_rhs
from .unicycle2 import Unicycle2, unicycle2_rhs

__all__ = [
    "Unicycle", "unicycle_rhs", "Unicycle2", "unicycle2_rhs",
    "DiffDrive", "diffdrive_rhs", "wheels_to_twist", "twist_to_wheels",
    "Ackermann", "ackermann_rhs", "SingleIntegrator", "DoubleIntegrator",
    "Quadrotor", "QuadrotorVelocityControl", "velocity_controlled_quadrotor",
    "VelocityControlledQuadrotor",
    "quadrotor_rhs", "mixer_matrix", "rotors_to_wrench", "wrench_to_rotors",
    "Blimp", "blimp_rhs",
    "quat_mul", "quat_normalize", "quat_rotate", "quat_to_rotmat", "quat_yaw",
    "quat_from_euler", "quat_derivative",
]
