"""``ReplayTracker`` / ``ReplayGlove``: play back recorded device streams (see recorder.py).

realtime=True: sample i becomes current when ``t_i - t_0`` seconds have passed since
``connect()`` (host ``clock``), and is returned with ``timestamp_s = t_start + (t_i - t_0)``, i.e.
rebased onto the host clock so latencies stay meaningful. realtime=False (as fast as possible):
each ``read()`` returns the next sample unchanged (original timestamps).

After the last sample (realtime: once ``t_last - t_0`` plus one median sample period has passed)
the stream is ``finished`` and ``read()`` returns the last sample marked invalid / disconnected,
so an agent holds its command. loop=True restarts from the first sample instead (realtime period
= span + one median sample period).
"""

from __future__ import annotations

import bisect
import collections
import dataclasses
import pathlib
import time
from typing import Callable, Generic, Sequence, TypeVar

import numpy as np

from .base import GloveSample, HapticGlove, PoseTracker, TrackerSample, check_haptics, require_connected
from .recorder import KINDS, load_stream

_S = TypeVar("_S", TrackerSample, GloveSample)


def _load(source, kind: str) -> tuple:
    if isinstance(source, (str, pathlib.Path)):
        stream = load_stream(source)
        if stream.kind != kind:
            raise ValueError(f"{source} holds a {stream.kind} stream, expected {kind}")
        samples = stream.samples
    else:
        samples = tuple(source)
    cls = KINDS[kind]
    if not samples:
        raise ValueError(f"a {kind} replay needs at least one sample, got none")
    for s in samples:
        if not isinstance(s, cls):
            raise TypeError(f"a {kind} replay takes {cls.__name__} samples, got {type(s).__name__}")
    t = np.array([s.timestamp_s for s in samples])
    if np.any(np.diff(t) < 0):
        i = int(np.argmax(np.diff(t) < 0))
        raise ValueError(f"sample timestamps must not decrease, got {t[i]} then {t[i + 1]} at index {i}")
    return samples


class _Playback:
    def __init__(self, samples: Sequence, realtime: bool, loop: bool, clock: Callable[[], float]):
        self.samples = samples
        self.realtime = bool(realtime)
        self.loop = bool(loop)
        self.clock = clock
        t = np.array([s.timestamp_s for s in samples])
        self.rel = (t - t[0]).tolist()
        self.period = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
        self.span = self.rel[-1] + self.period
        self.start: float | None = None
        self.next_index = 0
        self.finished = False

    def begin(self) -> None:
        self.start = self.clock()
        self.next_index = 0
        self.finished = False

    def current(self) -> tuple[int, float] | None:
        """(sample index, rebased timestamp or None) or None once finished."""
        if not self.realtime:
            if self.next_index >= len(self.samples):
                if not self.loop:
                    self.finished = True
                    return None
                self.next_index = 0
            i = self.next_index
            self.next_index += 1
            return i, None
        elapsed = self.clock() - self.start
        lap = 0
        if elapsed > self.span:
            if not self.loop or self.span <= 0:
                self.finished = True
                return None
            lap = int(elapsed // self.span)
            elapsed -= lap * self.span
        i = max(0, bisect.bisect_right(self.rel, elapsed) - 1)
        return i, self.start + lap * self.span + self.rel[i]


class _ReplayDevice(Generic[_S]):
    """Shared by ReplayTracker/ReplayGlove (sample type ``_S``): lifecycle and ``read()``. Once the
    stream is finished, ``read()`` returns the last sample with ``_LIVE_FIELD`` False, stamped now."""

    _LIVE_FIELD: str

    def _init_playback(self, source, kind: str, realtime: bool, loop: bool, clock: Callable[[], float]) -> None:
        self._pb = _Playback(_load(source, kind), realtime, loop, clock)
        self._connected = False

    def connect(self) -> None:
        self._pb.begin()
        self._connected = True

    def disconnect(self) -> None:
        self._connected = False

    @property
    def is_connected(self) -> bool:
        return self._connected

    @property
    def finished(self) -> bool:
        return self._pb.finished

    def read(self) -> _S:
        require_connected(self, "read")
        cur = self._pb.current()
        if cur is None:
            last = self._pb.samples[-1]
            return dataclasses.replace(last, **{self._LIVE_FIELD: False, "timestamp_s": self._pb.clock()})
        i, t = cur
        s = self._pb.samples[i]
        return s if t is None else dataclasses.replace(s, timestamp_s=t)


class ReplayTracker(_ReplayDevice[TrackerSample], PoseTracker):
    """PoseTracker that plays back a recorded tracker stream (file path or list of samples)."""

    _LIVE_FIELD = "valid"

    def __init__(self, source, *, realtime: bool = True, loop: bool = False, clock: Callable[[], float] = time.monotonic):
        self._init_playback(source, "tracker", realtime, loop, clock)


class ReplayGlove(_ReplayDevice[GloveSample], HapticGlove):
    """HapticGlove that plays back a recorded glove stream; haptic commands are validated and
    kept in ``haptics_log`` as (host time, force_feedback [5], vibration [5], duration s)."""

    _LIVE_FIELD = "connected"

    def __init__(self, source, *, realtime: bool = True, loop: bool = False, clock: Callable[[], float] = time.monotonic):
        self._init_playback(source, "glove", realtime, loop, clock)
        self.haptics_log: collections.deque = collections.deque(maxlen=100_000)

    def send_haptics(self, force_feedback, vibration, vibration_duration_s: float) -> bool:
        ff, vib, dur = check_haptics(force_feedback, vibration, vibration_duration_s)
        require_connected(self, "send_haptics")
        self.haptics_log.append((self._pb.clock(), ff, vib, dur))
        return True
