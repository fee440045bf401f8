"""Recording of device streams, and loading them back (for ``ReplayTracker``/``ReplayGlove``).

Two formats, picked by the file suffix:

* ``.jsonl`` (crash-safe, for live sessions): a header line
  ``{"format": "defgrasp-teleop-stream", "version": 1, "kind": "tracker"|"glove"}`` then one JSON
  object per sample, flushed as written: a crash loses at most the line being written, and
  ``load_stream`` skips such a torn last line with a warning. Tracker lines:
  ``{"t": s, "valid": bool, "pose": 4x4}``; glove lines: ``{"t": s, "connected": bool,
  "joint_angles": 5x4 rad, "fingertip_positions": 5x3 m}``. Floats round-trip exactly.
* ``.npz`` (compact): arrays ``format``, ``version``, ``kind``, ``timestamp_s`` [N] and
  ``valid`` [N] bool + ``pose`` [N,4,4] (tracker) or ``connected`` [N] bool + ``joint_angles``
  [N,5,4] + ``fingertip_positions`` [N,5,3] (glove); written to a temporary file on ``close()``
  and moved into place atomically, so a crash leaves no half-written file.
"""

from __future__ import annotations

import json
import logging
import os
import pathlib
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np

from .base import GloveSample, HapticGlove, PoseTracker, TrackerSample

log = logging.getLogger("teleop.recorder")

FORMAT = "defgrasp-teleop-stream"
FORMAT_VERSION = 1
KINDS = {"tracker": TrackerSample, "glove": GloveSample}
_S = TypeVar("_S", TrackerSample, GloveSample)
SUFFIXES = (".jsonl", ".npz")


@dataclass(frozen=True)
class Stream:
    kind: str  # "tracker" or "glove"
    samples: tuple


def _suffix(path: pathlib.Path) -> str:
    if path.suffix not in SUFFIXES:
        raise ValueError(f"stream file must end in one of {SUFFIXES}, got {str(path)!r}")
    return path.suffix


def _sample_to_json(s) -> dict:
    if isinstance(s, TrackerSample):
        return {"t": s.timestamp_s, "valid": s.valid, "pose": s.pose.tolist()}
    return {"t": s.timestamp_s, "connected": s.connected, "joint_angles": s.joint_angles.tolist(),
            "fingertip_positions": s.fingertip_positions.tolist()}


def _sample_from_json(kind: str, d: dict):
    if kind == "tracker":
        return TrackerSample(np.array(d["pose"]), bool(d["valid"]), float(d["t"]))
    return GloveSample(np.array(d["joint_angles"]), np.array(d["fingertip_positions"]), bool(d["connected"]), float(d["t"]))


class StreamRecorder:
    """Append samples of one kind to a ``.jsonl`` or ``.npz`` file; ``close()`` when done."""

    def __init__(self, path, kind: str, *, overwrite: bool = False):
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {tuple(KINDS)}, got {kind!r}")
        self.path = pathlib.Path(path)
        self.kind = kind
        self._suffix = _suffix(self.path)
        if self.path.exists() and not overwrite:
            raise FileExistsError(f"{self.path} exists; pass overwrite=True to replace it")
        self.count = 0
        self._rows: list = []
        self._fh = None
        if self._suffix == ".jsonl":
            self._fh = open(self.path, "w", encoding="utf-8")
            self._write_line({"format": FORMAT, "version": FORMAT_VERSION, "kind": kind})
        self._closed = False

    def _write_line(self, obj: dict) -> None:
        self._fh.write(json.dumps(obj) + "\n")
        self._fh.flush()

    def append(self, sample) -> None:
        if self._closed:
            raise RuntimeError(f"recorder for {self.path} is closed")
        if not isinstance(sample, KINDS[self.kind]):
            raise TypeError(f"a {self.kind} recorder takes {KINDS[self.kind].__name__}, got {type(sample).__name__}")
        if self._fh is not None:
            self._write_line(_sample_to_json(sample))
        else:
            self._rows.append(sample)
        self.count += 1

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._fh is not None:
            os.fsync(self._fh.fileno())
            self._fh.close()
            return
        s = self._rows
        arrays = {"format": np.array(FORMAT), "version": np.array(FORMAT_VERSION), "kind": np.array(self.kind),
                  "timestamp_s": np.array([x.timestamp_s for x in s], dtype=np.float64)}
        if self.kind == "tracker":
            arrays["valid"] = np.array([x.valid for x in s], dtype=bool)
            arrays["pose"] = np.array([x.pose for x in s], dtype=np.float64).reshape(len(s), 4, 4)
        else:
            arrays["connected"] = np.array([x.connected for x in s], dtype=bool)
            arrays["joint_angles"] = np.array([x.joint_angles for x in s], dtype=np.float64).reshape(len(s), 5, 4)
            arrays["fingertip_positions"] = np.array([x.fingertip_positions for x in s], dtype=np.float64).reshape(len(s), 5, 3)
        tmp = self.path.with_name(self.path.name + ".tmp.npz")
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def load_stream(path) -> Stream:
    """Load a recorded stream (``.jsonl`` or ``.npz``); ValueError on anything not a stream file."""
    path = pathlib.Path(path)
    if _suffix(path) == ".npz":
        with np.load(path, allow_pickle=False) as z:
            if "format" not in z or str(z["format"]) != FORMAT:
                raise ValueError(f"{path} is not a {FORMAT} file")
            if int(z["version"]) != FORMAT_VERSION:
                raise ValueError(f"{path}: stream format version {int(z['version'])} unsupported (expected {FORMAT_VERSION})")
            kind, t = str(z["kind"]), z["timestamp_s"]
            if kind == "tracker":
                samples = tuple(TrackerSample(z["pose"][i], bool(z["valid"][i]), float(t[i])) for i in range(len(t)))
            elif kind == "glove":
                samples = tuple(GloveSample(z["joint_angles"][i], z["fingertip_positions"][i], bool(z["connected"][i]), float(t[i])) for i in range(len(t)))
            else:
                raise ValueError(f"{path}: kind must be one of {tuple(KINDS)}, got {kind!r}")
        return Stream(kind, samples)
    lines = path.read_text(encoding="utf-8").split("\n")
    try:
        header = json.loads(lines[0])
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: first line is not a JSON header") from exc
    if header.get("format") != FORMAT or header.get("version") != FORMAT_VERSION or header.get("kind") not in KINDS:
        raise ValueError(f"{path}: header must be {{format: {FORMAT}, version: {FORMAT_VERSION}, kind: tracker|glove}}, got {header}")
    kind = header["kind"]
    body = lines[1:]
    samples = []
    for i, line in enumerate(body):
        if not line.strip():
            continue
        try:
            samples.append(_sample_from_json(kind, json.loads(line)))
        except (json.JSONDecodeError, KeyError) as exc:
            if i == len(body) - 1:  # no newline after it: the write was cut short
                log.warning("%s: skipped a torn last line (recording interrupted?)", path)
                break
            raise ValueError(f"{path}:{i + 2}: bad sample line: {exc}") from exc
    return Stream(kind, tuple(samples))


class _RecordingDevice(Generic[_S]):
    """Shared by RecordingTracker/RecordingGlove (sample type ``_S``): lifecycle delegated to
    ``inner``, every ``read()`` sample appended to ``recorder`` (closed on ``disconnect()``)."""

    def _wrap(self, owner: str, kind: str, inner, recorder: StreamRecorder) -> None:
        if recorder.kind != kind:
            raise ValueError(f"{owner} needs a {kind!r} recorder, got {recorder.kind!r}")
        self.inner, self.recorder = inner, recorder

    def connect(self) -> None:
        self.inner.connect()

    def disconnect(self) -> None:
        self.inner.disconnect()
        self.recorder.close()

    @property
    def is_connected(self) -> bool:
        return self.inner.is_connected

    def read(self) -> _S:
        s = self.inner.read()
        self.recorder.append(s)
        return s


class RecordingTracker(_RecordingDevice[TrackerSample], PoseTracker):
    """Wraps a PoseTracker and records every ``read()`` sample to ``recorder``."""

    def __init__(self, tracker: PoseTracker, recorder: StreamRecorder):
        self._wrap("RecordingTracker", "tracker", tracker, recorder)


class RecordingGlove(_RecordingDevice[GloveSample], HapticGlove):
    """Wraps a HapticGlove and records every ``read()`` sample; haptics pass through."""

    def __init__(self, glove: HapticGlove, recorder: StreamRecorder):
        self._wrap("RecordingGlove", "glove", glove, recorder)

    def send_haptics(self, force_feedback, vibration, vibration_duration_s: float) -> bool:
        return self.inner.send_haptics(force_feedback, vibration, vibration_duration_s)
