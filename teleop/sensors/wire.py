"""Wire format of the defgrasp teleop UDP protocol, version 1 (see GLOVE_PROTOCOL.md).

Every datagram = 24-byte header + payload + CRC-32, all little-endian, no padding:

    header  <4s B B H I I d   magic b"DGTP", version, msg_type, flags, stream_id, sequence, t_sender_s
    payload depends on msg_type
    crc     <I                zlib.crc32 of header + payload

``decode`` raises ``ProtocolError`` (a ValueError) with the reason for anything malformed.
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass

import numpy as np

from .base import MAX_FINGERTIP_M, MAX_JOINT_ANGLE_RAD, MAX_VIBRATION_S

MAGIC = b"DGTP"
VERSION = 1

MSG_GLOVE_STATE = 1
MSG_GLOVE_HAPTICS = 2
MSG_TRACKER_POSE = 3
MSG_NAMES = {MSG_GLOVE_STATE: "glove_state", MSG_GLOVE_HAPTICS: "glove_haptics", MSG_TRACKER_POSE: "tracker_pose"}

# glove_state flags
FLAG_GLOVE_CONNECTED = 1 << 0
FLAG_RIGHT_HAND = 1 << 1
# tracker_pose flags
FLAG_POSE_VALID = 1 << 0
FLAG_DEVICE_CONNECTED = 1 << 1

HEADER = struct.Struct("<4sBBHIId")
CRC = struct.Struct("<I")
PAYLOADS = {
    MSG_GLOVE_STATE: struct.Struct("<35f"),  # 20 joint angles rad + 15 fingertip coords m
    MSG_GLOVE_HAPTICS: struct.Struct("<11f"),  # 5 force feedback + 5 vibration (0..1) + duration s
    MSG_TRACKER_POSE: struct.Struct("<7f"),  # position m + quaternion (x, y, z, w)
}
SIZES = {t: HEADER.size + p.size + CRC.size for t, p in PAYLOADS.items()}  # 168, 72, 56 bytes
MAX_DATAGRAM = max(SIZES.values())
#: |norm(q) - 1| accepted on the wire (float32 rounding is ~1e-7)
QUAT_NORM_TOL = 1e-3


class ProtocolError(ValueError):
    """A datagram that is not a valid protocol-v1 message."""


@dataclass(frozen=True)
class Header:
    msg_type: int
    flags: int
    stream_id: int
    sequence: int
    t_sender_s: float


@dataclass(frozen=True)
class Message:
    """A decoded datagram: the header plus the payload as float64 arrays."""

    header: Header
    values: np.ndarray  # flat payload, float64


def encode(msg_type: int, flags: int, stream_id: int, sequence: int, t_sender_s: float, values) -> bytes:
    """Pack one datagram. ``values`` is the flat payload (length fixed by ``msg_type``)."""
    if msg_type not in PAYLOADS:
        raise ValueError(f"msg_type must be one of {sorted(PAYLOADS)}, got {msg_type!r}")
    for name, v, hi in (("flags", flags, 0xFFFF), ("stream_id", stream_id, 0xFFFFFFFF), ("sequence", sequence, 0xFFFFFFFF)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= int(v) <= hi:
            raise ValueError(f"{name} must be an int in [0, {hi}], got {v!r}")
    if not math.isfinite(float(t_sender_s)):
        raise ValueError(f"t_sender_s must be finite, got {t_sender_s!r}")
    payload = PAYLOADS[msg_type]
    vals = np.asarray(values, dtype=np.float64).ravel()
    if vals.size != _count(payload):
        raise ValueError(f"{MSG_NAMES[msg_type]} payload needs {_count(payload)} values, got {vals.size}")
    body = HEADER.pack(MAGIC, VERSION, msg_type, int(flags), int(stream_id), int(sequence), float(t_sender_s))
    body += payload.pack(*vals.tolist())
    return body + CRC.pack(zlib.crc32(body))


def _count(s: struct.Struct) -> int:
    return s.size // 4


def decode(data: bytes) -> Message:
    """Unpack and validate one datagram; raises ProtocolError with the reason."""
    if len(data) < HEADER.size + CRC.size:
        raise ProtocolError(f"datagram too short: {len(data)} bytes")
    magic, version, msg_type, flags, stream_id, sequence, t_sender = HEADER.unpack_from(data)
    if magic != MAGIC:
        raise ProtocolError(f"bad magic {magic!r} (expected {MAGIC!r})")
    if version != VERSION:
        raise ProtocolError(f"unsupported protocol version {version} (this receiver speaks {VERSION})")
    if msg_type not in PAYLOADS:
        raise ProtocolError(f"unknown msg_type {msg_type}")
    if len(data) != SIZES[msg_type]:
        raise ProtocolError(f"{MSG_NAMES[msg_type]} must be {SIZES[msg_type]} bytes, got {len(data)}")
    (crc,) = CRC.unpack_from(data, len(data) - CRC.size)
    if crc != zlib.crc32(data[: -CRC.size]):
        raise ProtocolError("CRC-32 mismatch")
    if not math.isfinite(t_sender):
        raise ProtocolError(f"non-finite sender timestamp {t_sender!r}")
    values = np.array(PAYLOADS[msg_type].unpack_from(data, HEADER.size), dtype=np.float64)
    if not np.all(np.isfinite(values)):
        raise ProtocolError("non-finite payload value")
    _check_payload(msg_type, values)
    return Message(Header(msg_type, flags, stream_id, sequence, t_sender), values)


def _check_payload(msg_type: int, v: np.ndarray) -> None:
    if msg_type == MSG_GLOVE_STATE:
        if np.any(np.abs(v[:20]) > MAX_JOINT_ANGLE_RAD):
            raise ProtocolError(f"joint angle outside [-2pi, 2pi] rad: {v[:20].tolist()}")
        if np.any(np.abs(v[20:]) > MAX_FINGERTIP_M):
            raise ProtocolError(f"fingertip coordinate outside [-1, 1] m (mm sent instead of m?): {v[20:].tolist()}")
    elif msg_type == MSG_GLOVE_HAPTICS:
        if np.any(v[:10] < 0.0) or np.any(v[:10] > 1.0):
            raise ProtocolError(f"haptic level outside [0, 1]: {v[:10].tolist()}")
        if not 0.0 <= v[10] <= MAX_VIBRATION_S:
            raise ProtocolError(f"vibration duration outside [0, {MAX_VIBRATION_S}] s: {v[10]}")
    elif msg_type == MSG_TRACKER_POSE:
        n = float(np.linalg.norm(v[3:7]))
        if abs(n - 1.0) > QUAT_NORM_TOL:
            raise ProtocolError(f"quaternion norm {n:.6f} is not 1 (tolerance {QUAT_NORM_TOL})")


def seq_newer(seq: int, last: int) -> bool:
    """RFC 1982 serial-number order on uint32: is ``seq`` after ``last`` (wrap-around safe)?"""
    d = (seq - last) & 0xFFFFFFFF
    return 0 < d < 0x80000000
