"""SenseGlove DK1 over UDP: ``UdpGloveReceiver`` (a HapticGlove) and the reference ``UdpGloveSender``.

The DK1 SDK (SGConnect/SGCore) is C++; a small sender next to it (or next to the senseglove ROS
node) streams ``glove_state`` datagrams to the receiver and listens for ``glove_haptics`` datagrams
that the receiver sends back to the sender's source address. Format: GLOVE_PROTOCOL.md.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .base import JOINTS_PER_FINGER, N_FINGERS, GloveSample, HapticGlove, check_haptics, require_connected
from .udp_common import UdpReceiverDevice, UdpSenderDevice, UdpStreamSender
from .wire import (
    FLAG_GLOVE_CONNECTED, FLAG_RIGHT_HAND, MSG_GLOVE_HAPTICS, MSG_GLOVE_STATE, ProtocolError, decode, encode, seq_newer,
)

log = logging.getLogger("teleop.udp")

DEFAULT_GLOVE_PORT = 47001


@dataclass(frozen=True)
class HapticsCommand:
    """A decoded ``glove_haptics`` datagram, as the sender side sees it."""

    force_feedback: np.ndarray  # [5] 0..1, thumb..pinky
    vibration: np.ndarray  # [5] 0..1
    vibration_duration_s: float
    sequence: int
    t_sender_s: float  # receiver-side (defgrasp host) clock when it was sent


class UdpGloveReceiver(UdpReceiverDevice, HapticGlove):
    """HapticGlove fed by ``glove_state`` datagrams on ``host:port`` (non-blocking, latest wins).

    ``read()`` returns the newest accepted sample with ``connected`` = the sender's
    glove-connected flag, or ``connected=False`` once nothing was accepted for ``timeout_s``.
    ``timestamp_s`` is the host receive time (``clock``). ``send_haptics`` sends a
    ``glove_haptics`` datagram to ``haptics_address`` or, by default, to the source address of the
    latest accepted glove datagram. Drop counters: ``stats``.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = DEFAULT_GLOVE_PORT,
        *,
        timeout_s: float = 0.25,
        max_delay_s: float = 0.1,
        haptics_address: tuple[str, int] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ):
        self._init_rx(MSG_GLOVE_STATE, host, port, timeout_s, max_delay_s, clock)
        if haptics_address is not None and not (isinstance(haptics_address, tuple) and len(haptics_address) == 2):
            raise ValueError(f"haptics_address must be a (host, port) tuple or None, got {haptics_address!r}")
        self.haptics_address = haptics_address
        self._haptics_seq = 0
        self._last_angles = np.zeros((N_FINGERS, JOINTS_PER_FINGER))
        self._last_tips = np.zeros((N_FINGERS, 3))
        self.right_hand: bool | None = None

    def read(self) -> GloveSample:
        msg, t_recv, live = self._poll_rx()
        if msg is None:
            return GloveSample(self._last_angles, self._last_tips, False, self._clock())
        v = msg.values
        self._last_angles = v[:20].reshape(N_FINGERS, JOINTS_PER_FINGER)
        self._last_tips = v[20:].reshape(N_FINGERS, 3)
        self.right_hand = bool(msg.header.flags & FLAG_RIGHT_HAND)
        connected = live and bool(msg.header.flags & FLAG_GLOVE_CONNECTED)
        return GloveSample(self._last_angles, self._last_tips, connected, t_recv if live else self._clock())

    def send_haptics(self, force_feedback, vibration, vibration_duration_s: float) -> bool:
        ff, vib, dur = check_haptics(force_feedback, vibration, vibration_duration_s)
        require_connected(self, "send_haptics")
        dest = self.haptics_address or self._rx.peer
        if dest is None:
            return False
        self._haptics_seq = (self._haptics_seq + 1) & 0xFFFFFFFF
        data = encode(MSG_GLOVE_HAPTICS, 0, 0, self._haptics_seq, self._clock(), np.concatenate([ff, vib, [dur]]))
        try:
            self._rx.sendto(data, dest)
        except OSError as exc:
            log.warning("UDP glove: haptics to %s failed: %s", dest, exc)
            return False
        return True


class UdpGloveSender(UdpSenderDevice):
    """Reference sender (what a SGCore / ROS bridge does), also used by the tests.

    ``send(joint_angles [5,4] rad, fingertip_positions [5,3] m)`` emits one ``glove_state``
    datagram; ``poll_haptics()`` returns the newest ``glove_haptics`` command sent back to this
    sender's socket (or None). Malformed or out-of-order haptics datagrams are dropped and counted
    in ``haptics_dropped``.
    """

    def __init__(
        self,
        destination: tuple[str, int],
        *,
        bind_host: str = "0.0.0.0",
        bind_port: int = 0,
        stream_id: int | None = None,
        right_hand: bool = True,
        clock: Callable[[], float] = time.monotonic,
    ):
        self._tx = UdpStreamSender(MSG_GLOVE_STATE, destination, bind_host=bind_host, bind_port=bind_port, stream_id=stream_id, clock=clock)
        self.right_hand = bool(right_hand)
        self.haptics_dropped = 0
        self._last_haptics_seq: int | None = None

    @property
    def address(self) -> tuple[str, int]:
        return self._tx.address

    def send(
        self,
        joint_angles,
        fingertip_positions,
        *,
        connected: bool = True,
        timestamp_s: float | None = None,
        sequence: int | None = None,
    ) -> int:
        """Send one glove_state datagram (values validated like GloveSample); returns its sequence."""
        s = GloveSample(joint_angles, fingertip_positions, bool(connected), 0.0)  # validation
        flags = (FLAG_GLOVE_CONNECTED if connected else 0) | (FLAG_RIGHT_HAND if self.right_hand else 0)
        values = np.concatenate([s.joint_angles.ravel(), s.fingertip_positions.ravel()])
        return self._tx.send_values(flags, values, timestamp_s=timestamp_s, sequence=sequence)

    def poll_haptics(self) -> HapticsCommand | None:
        """Newest valid haptics command received since the last poll, or None."""
        newest = None
        for data in self._tx.recv_all():
            try:
                msg = decode(data)
                if msg.header.msg_type != MSG_GLOVE_HAPTICS:
                    raise ProtocolError(f"unexpected msg_type {msg.header.msg_type} on the haptics channel")
            except ProtocolError as exc:
                self.haptics_dropped += 1
                log.warning("UDP glove sender dropped a haptics datagram: %s (%d so far)", exc, self.haptics_dropped)
                continue
            h, v = msg.header, msg.values
            if self._last_haptics_seq is not None and not seq_newer(h.sequence, self._last_haptics_seq):
                self.haptics_dropped += 1
                continue
            self._last_haptics_seq = h.sequence
            newest = HapticsCommand(v[:5].copy(), v[5:10].copy(), float(v[10]), h.sequence, h.t_sender_s)
        return newest
