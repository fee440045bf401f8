"""How far the kinematic pad boxes can move in a control period, and how many substeps that needs.

With continuous contact detection (``kernels.pad_faces.contact_face``) a pad cannot push nodes out of
its far side however far it moves in a substep, but the contact face is found along the straight
relative motion of each node, and one Newton solve has to absorb the whole move; both stay accurate
while a pad point travels at most ``MAX_PAD_TRAVEL`` per substep (well under the 16 mm thickness of
the env's pad collision boxes). The count is a function of the configuration (the largest legal
move), never of the actions: every world of a batch, and a single env replaying one of them, steps
with the same substeps, so results do not depend on what the other worlds do.
"""

from __future__ import annotations

import math


#: Largest travel (m) of any point of a pad box in one physics substep (under the 16 mm box
#: thickness; at the env's default speeds the worst legal step then needs the default 4 substeps).
MAX_PAD_TRAVEL = 0.013


def max_pad_travel(linear_step: float, angle_step: float, reach: float, jaw_step: float) -> float:
    """Bound (m) on the travel of any pad-box point in one control period: a flange translation of
    at most ``linear_step`` (m), a rotation of at most ``angle_step`` (rad) about the flange, pad
    points at most ``reach`` (m) from the flange, and a jaw gap change of at most ``jaw_step`` (m,
    each pad moves half of it)."""
    return linear_step + 2.0 * math.sin(min(angle_step, math.pi) / 2.0) * reach + jaw_step / 2.0


def substeps_for_travel(travel: float, minimum: int, max_travel: float = MAX_PAD_TRAVEL) -> int:
    """Substeps of one control period (at least ``minimum``) in which no pad point moves more than
    ``max_travel`` (m) per substep, for a travel bound ``travel`` (m) over the period."""
    return max(int(minimum), math.ceil(float(travel) / max_travel - 1e-9))
