"""The labs by number: their titles, templates and checks."""

from __future__ import annotations

from ..core.errors import ParameterError
from . import (
    lab1_kinematics,
    lab2_go_to_goal,
    lab3_formation,
    lab4_consensus,
    lab5_safety,
    lab6_robots,
    lab7_learning,
    lab8_estimation,
)
from .grading import Lab

#: the labs, in order
LABS: tuple[Lab, ...] = (lab1_kinematics.LAB, lab2_go_to_goal.LAB, lab3_formation.LAB,
                          lab4_consensus.LAB, lab5_safety.LAB, lab6_robots.LAB, lab7_learning.LAB,
                          lab8_estimation.LAB)


def labs() -> list[Lab]:
    """Every lab, in order."""
    return list(LABS)


def get(number) -> Lab:
    """The lab numbered ``number``; :class:`ParameterError` naming the
    numbers there are otherwise."""
    known = {lab.number: lab for lab in LABS}
    try:
        return known[int(number)]
    except (KeyError, ValueError, TypeError):
        raise ParameterError("no such lab", param="lab",
                             expected=f"one of {sorted(known)}", found=number) from None
