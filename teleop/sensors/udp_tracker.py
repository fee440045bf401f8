"""Pose streams over UDP: ``UdpTrackerReceiver`` (a PoseTracker) and the reference ``UdpTrackerSender``.

Same design and receiver rules as the glove stream (GLOVE_PROTOCOL.md), message ``tracker_pose``:
position [3] m + quaternion (x, y, z, w) in the tracker system's frame (OpenVR standing universe).
Use it to bridge a tracker that lives on another machine (SteamVR on Windows, libsurvive, a ROS
``PoseStamped`` topic).
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from .base import PoseTracker, TrackerSample
from .udp_common import UdpReceiverDevice, UdpSenderDevice, UdpStreamSender
from .wire import FLAG_DEVICE_CONNECTED, FLAG_POSE_VALID, MSG_TRACKER_POSE
from ..se3 import check_rigid, matrix_to_pose, pose_to_matrix

DEFAULT_TRACKER_PORT = 47002


class UdpTrackerReceiver(UdpReceiverDevice, PoseTracker):
    """PoseTracker fed by ``tracker_pose`` datagrams on ``host:port`` (non-blocking, latest wins).

    ``read()``: ``valid`` = pose-valid and device-connected flags of the newest accepted datagram,
    and False once nothing was accepted for ``timeout_s``; ``timestamp_s`` = host receive time.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = DEFAULT_TRACKER_PORT,
        *,
        timeout_s: float = 0.25,
        max_delay_s: float = 0.1,
        clock: Callable[[], float] = time.monotonic,
    ):
        self._init_rx(MSG_TRACKER_POSE, host, port, timeout_s, max_delay_s, clock)
        self._last_pose = np.eye(4)

    def read(self) -> TrackerSample:
        msg, t_recv, live = self._poll_rx()
        if msg is None:
            return TrackerSample(self._last_pose, False, self._clock())
        flags = msg.header.flags
        ok = bool(flags & FLAG_POSE_VALID) and bool(flags & FLAG_DEVICE_CONNECTED)
        if ok:  # an invalid pose keeps the last valid one (OpenVR reports garbage when lost)
            self._last_pose = pose_to_matrix(msg.values[:3], msg.values[3:7])
        return TrackerSample(self._last_pose, ok and live, t_recv if live else self._clock())


class UdpTrackerSender(UdpSenderDevice):
    """Reference sender of ``tracker_pose`` datagrams (bridges and tests)."""

    def __init__(
        self,
        destination: tuple[str, int],
        *,
        bind_host: str = "0.0.0.0",
        bind_port: int = 0,
        stream_id: int | None = None,
        clock: Callable[[], float] = time.monotonic,
    ):
        self._tx = UdpStreamSender(MSG_TRACKER_POSE, destination, bind_host=bind_host, bind_port=bind_port, stream_id=stream_id, clock=clock)

    def send(
        self,
        pose,
        *,
        valid: bool = True,
        connected: bool = True,
        timestamp_s: float | None = None,
        sequence: int | None = None,
    ) -> int:
        """Send a 4x4 rigid pose (m); returns the sequence number used."""
        pos, quat = matrix_to_pose(check_rigid("pose", pose))
        flags = (FLAG_POSE_VALID if valid else 0) | (FLAG_DEVICE_CONNECTED if connected else 0)
        return self._tx.send_values(flags, np.concatenate([pos, quat]), timestamp_s=timestamp_s, sequence=sequence)
