"""HTC VIVE tracker through SteamVR/OpenVR (optional ``openvr`` package: ``pip install defgrasp[vive]``).

Poses come from ``IVRSystem.getDeviceToAbsoluteTrackingPose(TrackingUniverseStanding, 0, n)``; the
tracker is the first (or the serial-numbered) ``TrackedDeviceClass_GenericTracker``. OpenVR's frame
is right-handed, +y up, +x right, -z forward, metres; the 3x4 ``mDeviceToAbsoluteTracking`` is
turned into a 4x4 by ``openvr_matrix_to_pose`` (re-orthonormalised: OpenVR ships float32).
SteamVR can run without a headset (null-driver settings).
"""

from __future__ import annotations

import importlib
import logging
import time
from typing import Any, Callable

import numpy as np

from .base import PoseTracker, TrackerSample, require_connected
from ..se3 import orthonormalize

INSTALL_HINT = "pip install defgrasp[vive]"
log = logging.getLogger("teleop.openvr")


def import_openvr():
    """Import pyopenvr lazily; ImportError naming the extra to install when it is missing."""
    try:
        return importlib.import_module("openvr")
    except ImportError as exc:
        raise ImportError(
            f"OpenVRTracker needs the optional 'openvr' package (pyopenvr) and a running SteamVR: "
            f"{INSTALL_HINT}"
        ) from exc


def openvr_matrix_to_pose(m34: Any) -> np.ndarray:
    """4x4 float64 pose from OpenVR's 3x4 row-major ``HmdMatrix34_t`` (or anything indexable
    as ``m[row][col]``, rows 0..2, cols 0..3). The rotation is projected to the nearest
    orthonormal matrix; ValueError if it is not finite or far from a rotation."""
    try:
        a = np.array([[float(m34[r][c]) for c in range(4)] for r in range(3)], dtype=np.float64)
    except (TypeError, IndexError, ValueError) as exc:
        raise ValueError(f"expected a 3x4 matrix indexable as m[row][col], got {m34!r}") from exc
    if not np.all(np.isfinite(a)):
        raise ValueError(f"OpenVR pose must be finite, got {a.tolist()}")
    R = a[:, :3]
    err = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if err > 1e-2 or np.linalg.det(R) <= 0:
        raise ValueError(f"OpenVR pose rotation is not a rotation (max|R^T R - I| = {err:.3g}): {a.tolist()}")
    T = np.eye(4)
    T[:3, :3] = orthonormalize(R)
    T[:3, 3] = a[:, 3]
    return T


class OpenVRTracker(PoseTracker):
    """PoseTracker for a VIVE tracker via pyopenvr (untestable without SteamVR).

    serial: the tracker's serial number (``Prop_SerialNumber_String``), or None for the first
        GenericTracker found. ``read()``: ``valid`` = ``bPoseIsValid and bDeviceIsConnected`` (and
        the tracker exists); an invalid reading carries the last valid pose; ``timestamp_s`` is
        the host time of the poll (``clock``).
    """

    def __init__(self, serial: str | None = None, *, clock: Callable[[], float] = time.monotonic):
        if serial is not None and (not isinstance(serial, str) or not serial):
            raise ValueError(f"serial must be a non-empty string or None, got {serial!r}")
        self.serial = serial
        self._clock = clock
        self._vr = None
        self._system = None
        self._index: int | None = None
        self._last_pose = np.eye(4)

    def connect(self) -> None:
        if self._system is not None:
            return
        vr = import_openvr()
        self._system = vr.init(vr.VRApplication_Other)
        self._vr = vr
        self._index = self._find_tracker()
        if self._index is None:
            self.disconnect()
            which = f"with serial {self.serial!r}" if self.serial else "of class TrackedDeviceClass_GenericTracker"
            raise RuntimeError(f"OpenVR: no tracker {which} is connected (is SteamVR running and the tracker paired?)")

    def _find_tracker(self) -> int | None:
        vr, system = self._vr, self._system
        for i in range(vr.k_unMaxTrackedDeviceCount):
            if system.getTrackedDeviceClass(i) != vr.TrackedDeviceClass_GenericTracker:
                continue
            if self.serial is None or system.getStringTrackedDeviceProperty(i, vr.Prop_SerialNumber_String) == self.serial:
                return i
        return None

    def disconnect(self) -> None:
        if self._vr is not None:
            self._vr.shutdown()
        self._vr = self._system = self._index = None

    @property
    def is_connected(self) -> bool:
        return self._system is not None

    def read(self) -> TrackerSample:
        require_connected(self, "read")
        vr = self._vr
        poses = self._system.getDeviceToAbsoluteTrackingPose(vr.TrackingUniverseStanding, 0, vr.k_unMaxTrackedDeviceCount)
        now = self._clock()
        p = poses[self._index]
        ok = bool(p.bPoseIsValid) and bool(p.bDeviceIsConnected)
        if ok:
            try:
                self._last_pose = openvr_matrix_to_pose(p.mDeviceToAbsoluteTracking)
            except ValueError as exc:
                log.warning("OpenVR: tracker %d reported an unusable pose, treated as lost: %s", self._index, exc)
                ok = False
        return TrackerSample(self._last_pose, ok, now)
