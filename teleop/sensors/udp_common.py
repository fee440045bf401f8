"""Receiver and sender cores shared by the UDP glove and tracker streams.

Receiver policy (GLOVE_PROTOCOL.md, "Receiver rules"):

* non-blocking socket, drained on every ``poll()``; the newest valid datagram of a drain wins (the
  older ones count as ``superseded``);
* malformed datagrams (wrong size, magic, version, type, CRC, non-finite or out-of-range values)
  are dropped;
* one stream (``stream_id``) is followed at a time; another stream is taken over only after the
  current one has been silent for ``timeout_s`` (a restarted sender resumes after at most that);
* out-of-order or duplicate datagrams (sequence not newer, RFC 1982 order) are dropped;
* a stale newest datagram is dropped: its one-way delay ``t_recv - t_sender`` is compared with its
  minimum over the last ``DELAY_WINDOW`` accepted datagrams of the stream (that minimum absorbs the clock
  offset between sender and receiver, so no clock sync is needed); a datagram more than
  ``max_delay_s`` late relative to that baseline is stale;
* no accepted datagram for ``timeout_s`` -> the stream is reported disconnected, and the delay
  baseline is reset when data comes back.

Every drop is counted in ``stats`` and logged as a warning (first drop of each kind, then at most
once per ``WARN_INTERVAL_S`` with the running count).
"""

from __future__ import annotations

import collections
import logging
import secrets
import socket
import time
from dataclasses import dataclass, field
from typing import Callable

from .._validate import check_number, check_port
from .base import require_connected
from .wire import MAX_DATAGRAM, MSG_NAMES, Message, ProtocolError, decode, encode, seq_newer

log = logging.getLogger("teleop.udp")

DELAY_WINDOW = 256
WARN_INTERVAL_S = 1.0
MAX_DRAIN = 10_000


@dataclass
class ReceiverStats:
    """Counters of a UDP receiver since connect()."""

    received: int = 0
    accepted: int = 0  # became the latest sample
    superseded: int = 0  # valid, but a newer one arrived in the same drain (latest wins; no warning)
    malformed: int = 0
    out_of_order: int = 0
    stale: int = 0
    other_stream: int = 0
    last_sequence: int | None = None
    stream_id: int | None = None
    last_delay_excess_s: float = 0.0
    drops_by_reason: dict = field(default_factory=dict)

    @property
    def dropped(self) -> int:
        return self.malformed + self.out_of_order + self.stale + self.other_stream


def _drain(sock: socket.socket):
    """Yield (data, addr) for every datagram waiting on non-blocking ``sock`` (at most MAX_DRAIN)."""
    for _ in range(MAX_DRAIN):
        try:
            data, addr = sock.recvfrom(MAX_DATAGRAM + 1)
        except (BlockingIOError, InterruptedError):
            break
        except ConnectionResetError:  # ICMP port unreachable echoed on some platforms
            continue
        yield data, addr


def _check_host(name: str, host) -> str:
    if not isinstance(host, str) or not host:
        raise ValueError(f"{name} must be a non-empty host string such as '127.0.0.1', got {host!r}")
    return host


class UdpStreamReceiver:
    """Latest-sample-wins receiver of one message type (see module docstring)."""

    def __init__(
        self,
        msg_type: int,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        timeout_s: float = 0.25,
        max_delay_s: float = 0.1,
        clock: Callable[[], float] = time.monotonic,
    ):
        self._msg_type = msg_type
        self._host = _check_host("host", host)
        self._port = check_port("port", port)
        self.timeout_s = check_number("timeout_s", timeout_s, 0.0, 60.0, unit="s", lo_open=True)
        self.max_delay_s = check_number("max_delay_s", max_delay_s, 0.0, 60.0, unit="s", lo_open=True)
        if not callable(clock):
            raise TypeError(f"clock must be a callable returning seconds, got {clock!r}")
        self._clock = clock
        self._sock: socket.socket | None = None
        self._reset_state()

    def _reset_state(self) -> None:
        self.stats = ReceiverStats()
        self._latest: Message | None = None
        self._latest_t_recv = -float("inf")
        self._latest_addr = None
        self._delays: collections.deque = collections.deque(maxlen=DELAY_WINDOW)
        self._last_warn: dict[str, float] = {}

    # lifecycle ---------------------------------------------------------------------------------
    def open(self) -> None:
        if self._sock is not None:
            return
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self._host, self._port))
        except OSError as exc:
            sock.close()
            raise OSError(f"cannot bind UDP {self._host}:{self._port}: {exc}") from exc
        sock.setblocking(False)
        self._sock = sock
        self._reset_state()

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    @property
    def is_open(self) -> bool:
        return self._sock is not None

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) actually bound (port 0 resolves on open())."""
        if self._sock is None:
            raise RuntimeError("the receiver is not open: call connect() first")
        return self._sock.getsockname()

    # receiving -----------------------------------------------------------------------------------
    def poll(self) -> tuple[Message | None, float, bool]:
        """Drain the socket; return (latest accepted message or None, its receive time, live)."""
        if self._sock is None:
            raise RuntimeError("the receiver is not open: call connect() first")
        batch = []
        for data, addr in _drain(self._sock):
            msg = self._screen(data, addr, self._clock())
            if msg is not None:
                batch.append((msg, addr))
        if batch:
            self.stats.superseded += len(batch) - 1  # valid but older than the newest of this drain
            self._admit(*batch[-1], self._clock())
        live = (self._clock() - self._latest_t_recv) <= self.timeout_s
        return self._latest, self._latest_t_recv, live

    def _screen(self, data: bytes, addr, now: float) -> Message | None:
        """Format, stream and order checks; returns the message if it is the newest so far."""
        self.stats.received += 1
        try:
            msg = decode(data)
        except ProtocolError as exc:
            self._drop("malformed", f"{exc}", addr, now)
            return None
        h = msg.header
        if h.msg_type != self._msg_type:
            self._drop("malformed", f"unexpected {MSG_NAMES[h.msg_type]} on a {MSG_NAMES[self._msg_type]} port", addr, now)
            return None
        silent = (now - self._latest_t_recv) > self.timeout_s
        if self.stats.stream_id is not None and h.stream_id != self.stats.stream_id:
            if not silent:
                self._drop("other_stream", f"stream {h.stream_id:#x} while {self.stats.stream_id:#x} is live", addr, now)
                return None
            log.info("UDP %s: switching from stream %#x to %#x", MSG_NAMES[self._msg_type], self.stats.stream_id, h.stream_id)
            self.stats.last_sequence = None
        if self.stats.stream_id != h.stream_id or silent:
            self._delays.clear()  # new stream or resync after a timeout: new delay baseline
        if self.stats.last_sequence is not None and not seq_newer(h.sequence, self.stats.last_sequence):
            self._drop("out_of_order", f"sequence {h.sequence} not after {self.stats.last_sequence}", addr, now)
            return None
        self.stats.stream_id = h.stream_id
        self.stats.last_sequence = h.sequence
        return msg

    def _admit(self, msg: Message, addr, now: float) -> None:
        """Staleness check of the newest datagram of a drain, then make it the latest sample.

        Only the newest is checked: older datagrams of the same drain waited in the socket buffer
        for the poll, which is the reader's delay, not the stream's."""
        delay = now - msg.header.t_sender_s
        baseline = min(self._delays) if self._delays else delay
        excess = delay - baseline
        if excess > self.max_delay_s:
            self._drop("stale", f"{excess * 1e3:.1f} ms later than the stream's fastest datagram", addr, now)
            return
        self._delays.append(delay)
        self.stats.accepted += 1
        self.stats.last_delay_excess_s = max(0.0, excess)
        self._latest, self._latest_t_recv, self._latest_addr = msg, now, addr

    def _drop(self, reason: str, detail: str, addr, now: float) -> None:
        setattr(self.stats, reason, getattr(self.stats, reason) + 1)
        n = getattr(self.stats, reason)
        self.stats.drops_by_reason[reason] = n
        last = self._last_warn.get(reason)
        if last is None or now - last >= WARN_INTERVAL_S:
            self._last_warn[reason] = now
            log.warning(
                "UDP %s receiver dropped a %s datagram from %s: %s (%d %s drops so far)",
                MSG_NAMES[self._msg_type], reason, addr, detail, n, reason,
            )

    @property
    def peer(self):
        """Source address of the latest accepted datagram (None before the first one)."""
        return self._latest_addr

    def sendto(self, data: bytes, addr) -> None:
        if self._sock is None:
            raise RuntimeError("the receiver is not open: call connect() first")
        self._sock.sendto(data, addr)


class UdpStreamSender:
    """Sender core: one socket, a random ``stream_id``, an incrementing uint32 sequence."""

    def __init__(
        self,
        msg_type: int,
        destination: tuple[str, int],
        *,
        bind_host: str = "0.0.0.0",
        bind_port: int = 0,
        stream_id: int | None = None,
        clock: Callable[[], float] = time.monotonic,
    ):
        if not (isinstance(destination, tuple) and len(destination) == 2):
            raise ValueError(f"destination must be a (host, port) tuple, got {destination!r}")
        self.destination = (_check_host("destination host", destination[0]), check_port("destination port", destination[1]))
        if self.destination[1] == 0:
            raise ValueError("destination port must be in [1, 65535], got 0")
        if stream_id is None:
            stream_id = secrets.randbits(32)
        if isinstance(stream_id, bool) or not isinstance(stream_id, int) or not 0 <= stream_id <= 0xFFFFFFFF:
            raise ValueError(f"stream_id must be an int in [0, 4294967295], got {stream_id!r}")
        self.stream_id = stream_id
        self._msg_type = msg_type
        self._clock = clock
        self.sequence = 0
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((_check_host("bind_host", bind_host), check_port("bind_port", bind_port)))
        except OSError:
            self._sock.close()
            raise
        self._sock.setblocking(False)

    def send_values(self, flags: int, values, *, timestamp_s: float | None = None, sequence: int | None = None) -> int:
        """Send one datagram; returns the sequence number used. ``timestamp_s`` defaults to the
        sender clock now; ``sequence`` defaults to the next one (overrides are for bridges that
        carry their own stamps, and for tests)."""
        self._require_open()
        if sequence is None:
            self.sequence = (self.sequence + 1) & 0xFFFFFFFF
            sequence = self.sequence
        t = self._clock() if timestamp_s is None else check_number("timestamp_s", timestamp_s, unit="s")
        self._sock.sendto(encode(self._msg_type, flags, self.stream_id, sequence, t, values), self.destination)
        return sequence

    def send_raw(self, data: bytes) -> None:
        """Send arbitrary bytes (protocol testing)."""
        self._require_open()
        self._sock.sendto(bytes(data), self.destination)

    def recv_all(self) -> list[bytes]:
        """Drain datagrams sent back to this sender's socket (e.g. haptics)."""
        self._require_open()
        return [data for data, _ in _drain(self._sock)]

    @property
    def address(self) -> tuple[str, int]:
        self._require_open()
        return self._sock.getsockname()

    def _require_open(self) -> None:
        if self._sock is None:
            raise RuntimeError(f"{type(self).__name__} is closed")

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class UdpReceiverDevice:
    """Device side of a UDP receiver driver (glove, tracker): lifecycle, ``address`` and ``stats``
    delegated to the ``UdpStreamReceiver`` in ``self._rx``. Mix in before the device interface."""

    _rx: UdpStreamReceiver

    def _init_rx(self, msg_type: int, host, port, timeout_s, max_delay_s, clock: Callable[[], float]) -> None:
        self._rx = UdpStreamReceiver(msg_type, host, port, timeout_s=timeout_s, max_delay_s=max_delay_s, clock=clock)
        self._clock = clock

    def _poll_rx(self) -> tuple[Message | None, float, bool]:
        """``read()`` prologue: require connect(), then drain (see ``UdpStreamReceiver.poll``)."""
        require_connected(self, "read")
        return self._rx.poll()

    def connect(self) -> None:
        self._rx.open()

    def disconnect(self) -> None:
        self._rx.close()

    @property
    def is_connected(self) -> bool:
        return self._rx.is_open

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) the receiver is bound to."""
        return self._rx.address

    @property
    def stats(self):
        return self._rx.stats


class UdpSenderDevice:
    """Reference-sender side shared by the glove and tracker senders: ``stream_id``, ``send_raw``,
    ``close`` and the context manager, delegated to the ``UdpStreamSender`` in ``self._tx``."""

    _tx: UdpStreamSender

    @property
    def stream_id(self) -> int:
        return self._tx.stream_id

    def send_raw(self, data: bytes) -> None:
        """Send arbitrary bytes to the receiver (protocol tests)."""
        self._tx.send_raw(data)

    def close(self) -> None:
        self._tx.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
