"""How far the kinematic pad boxes move in a step, and how many substeps that needs (numpy, host).

With continuous contact detection (``kernels.contact.contact_face``) a pad cannot push nodes out of
its far side however far it moves in a substep, but the contact face is found along the straight
relative motion of each node, and one Newton solve has to absorb the whole move; both stay accurate
while a pad point travels at most ``MAX_PAD_TRAVEL`` per substep (well under the 16 mm thickness of
the env's pad collision boxes).
"""

from __future__ import annotations

import math

import numpy as np

from ..transforms import quat_rotate

#: Largest travel (m) of any point of a pad box in one physics substep.
MAX_PAD_TRAVEL = 0.01
_CORNER_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


def corner_travel(centers0, quats0, centers1, quats1, half_extents) -> np.ndarray:
    """Largest displacement (m) [W] of a pad-box corner between two poses: centres [W,P,3] (m),
    orientations [W,P,4] (xyzw), half extents [3] (m) of every box."""
    offsets = _CORNER_SIGNS * np.asarray(half_extents, dtype=np.float64)
    c0 = centers0[:, :, None, :] + quat_rotate(quats0[:, :, None, :], offsets)
    c1 = centers1[:, :, None, :] + quat_rotate(quats1[:, :, None, :], offsets)
    return np.linalg.norm(c1 - c0, axis=-1).reshape(len(c0), -1).max(axis=1)


def substeps_for_travel(travel, minimum: int, max_travel: float = MAX_PAD_TRAVEL) -> int:
    """Substeps of one step (at least ``minimum``) in which no pad point moves more than
    ``max_travel`` (m) per substep, for the travel (m) [W] of the worlds over the step."""
    return max(int(minimum), math.ceil(float(np.max(travel)) / max_travel - 1e-9))
