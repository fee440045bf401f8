"""Policies for ``DeformablePickup-v0`` that act from observations only.

``ScriptedPickupExpert``: a phase-scripted top-down pick-up expert (delta, absolute or top-down actions,
batched).
"""

from .grasp_planning import GraspPlan, plan_grasps
from .scripted_expert import PHASE_NAMES, RECOMMENDED_ENV_KWARGS, ExpertConfig, ScriptedPickupExpert

__all__ = ["ExpertConfig", "GraspPlan", "PHASE_NAMES", "RECOMMENDED_ENV_KWARGS", "ScriptedPickupExpert",
           "plan_grasps"]
