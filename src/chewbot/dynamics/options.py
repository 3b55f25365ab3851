"""The inverse dynamics' choices, by name: how the target's redundant actuation is distributed and how the HKP
planes hold the condyles. Standard library only: the command line reads them for its help without loading NumPy or
CasADi."""

from __future__ import annotations

from enum import StrEnum


class Goal(StrEnum):
    """What the optimal distribution of the target's redundant torques minimises (seed 001, Sect. 4.5, Eqs. 52-54)."""

    min_torque = "min-torque"  # G1: abs(tau)^2
    min_coupler_force = "min-coupler-force"  # G2: the forces at S_1..S_6
    min_hkp_force = "min-hkp-force"  # G3: N_L^2 + N_R^2


class Contact(StrEnum):
    """How the HKP planes hold the condyles (docs/contact.md)."""

    bilateral = "bilateral"  # a ball in a slot: the plane may push or pull (the papers' reading)
    unilateral = "unilateral"  # a ball pressed on a plane: N_L, N_R >= contact.preload_N


GOALS = tuple(g.value for g in Goal)
# The formulation a run uses where it names none, per orientation parametrisation (its keys are
# kinematics.options.Orientation's values; the rows are dynamics.registry's).
DEFAULT_METHOD = {"euler-angles": "hessian", "euler-parameters": "newton-euler"}
CONTACT_MODELS = tuple(c.value for c in Contact)


def check_goal(goal: str) -> None:
    """Raise ValueError unless ``goal`` is one of :data:`GOALS`."""
    if goal not in GOALS:
        raise ValueError(f"goal must be one of {', '.join(GOALS)}, not {goal!r}")


def check_contact(contact: str) -> None:
    """Raise ValueError unless ``contact`` is one of :data:`CONTACT_MODELS`."""
    if contact not in CONTACT_MODELS:
        raise ValueError(f"contact model must be one of {', '.join(CONTACT_MODELS)}, not {contact!r}")
