"""Recording keys (as LeRobot's ``record``): a pure key -> command map and pluggable key sources.

Keys (names are lower-case strings: ``"right"``, ``"left"``, ``"esc"``, single characters):

    right arrow   end the episode (keep it)          left arrow   discard it and record it again
    s             mark the episode a success (toggle) esc          stop (the current episode is kept)
    enter/space   start the episode now (without waiting for device data; ends a review early)

``command_for_key`` is the whole mapping; a ``KeySource`` only turns a device into key names:

* ``PynputKeySource``: global key events through ``pynput`` (needs a display; optional package);
* ``TerminalKeySource``: the controlling terminal in cbreak mode (no echo, no line buffering;
  Ctrl-C still interrupts), bytes decoded by the pure ``decode_terminal_keys``; a terminal only
  reports presses (and auto-repeat), so "held" means "pressed within the last ``hold_s``";
* ``NullKeySource``: no keys (headless runs end on the episode count or Ctrl-C);
* ``ScriptedKeySource``: keys at given poll counts or times (tests).

``make_key_source("auto")`` picks pynput, then the terminal, then none.
"""

from __future__ import annotations

import enum
import importlib
import importlib.util
import logging
import os
import sys
import threading
import time
from typing import Callable, Iterable, Mapping

log = logging.getLogger("teleop.app")


class RecordCommand(enum.Enum):
    END_EPISODE = "end_episode"
    RERECORD = "rerecord"
    MARK_SUCCESS = "mark_success"
    STOP = "stop"
    START_NOW = "start_now"


DEFAULT_RECORD_KEYS: Mapping[str, RecordCommand] = {
    "right": RecordCommand.END_EPISODE,
    "left": RecordCommand.RERECORD,
    "s": RecordCommand.MARK_SUCCESS,
    "esc": RecordCommand.STOP,
    "enter": RecordCommand.START_NOW,
    "space": RecordCommand.START_NOW,
}


def command_for_key(key: str, bindings: Mapping[str, RecordCommand] = DEFAULT_RECORD_KEYS) -> RecordCommand | None:
    """The recording command bound to ``key`` (a key name), or None for any other key."""
    if not isinstance(key, str):
        raise TypeError(f"key must be a key name string, got {key!r}")
    return bindings.get(key.lower())


def commands_for_keys(keys: Iterable[str], bindings: Mapping[str, RecordCommand] = DEFAULT_RECORD_KEYS) -> list[RecordCommand]:
    """Commands of a sequence of key presses, in order (unbound keys dropped)."""
    return [c for c in (command_for_key(k, bindings) for k in keys) if c is not None]


# terminal decoding -----------------------------------------------------------------------------------
_CSI_FINAL = {"A": "up", "B": "down", "C": "right", "D": "left", "H": "home", "F": "end"}
_CONTROL = {b"\r": "enter", b"\n": "enter", b"\t": "tab", b"\x7f": "backspace", b" ": "space"}


def decode_terminal_keys(data: bytes, *, final: bool = False) -> tuple[list[str], bytes]:
    """Key names in ``data`` (bytes read from a terminal in cbreak mode) and the undecoded tail.

    Arrows come as ``ESC [ A..D`` (or ``ESC O A..D``); a lone ``ESC`` is the Escape key, but a
    trailing one may be the start of a sequence still in transit, so it is returned as the tail
    unless ``final`` (no more bytes came within a short wait). Unknown escape sequences are
    skipped; other bytes decode as UTF-8 characters (control characters by name, others dropped).
    """
    if not isinstance(data, (bytes, bytearray)):
        raise TypeError(f"data must be bytes, got {type(data).__name__}")
    keys: list[str] = []
    i, n = 0, len(data)
    while i < n:
        b = data[i:i + 1]
        if b == b"\x1b":
            if i + 1 >= n:
                if final:
                    keys.append("esc")
                    i += 1
                    continue
                return keys, bytes(data[i:])
            nxt = data[i + 1:i + 2]
            if nxt in (b"[", b"O"):
                j = i + 2
                while j < n and not (0x40 <= data[j] <= 0x7E):  # parameter bytes until the final byte
                    j += 1
                if j >= n:
                    if final:  # a cut sequence: drop it
                        return keys, b""
                    return keys, bytes(data[i:])
                name = _CSI_FINAL.get(chr(data[j]))
                if name is not None:
                    keys.append(name)
                i = j + 1
                continue
            keys.append("esc")  # ESC followed by another key: Escape, then that key
            i += 1
            continue
        if b in _CONTROL:
            keys.append(_CONTROL[b])
            i += 1
            continue
        # one UTF-8 character (1..4 bytes)
        lead = data[i]
        width = 1 if lead < 0x80 else 2 if lead >> 5 == 0b110 else 3 if lead >> 4 == 0b1110 else 4 if lead >> 3 == 0b11110 else 1
        if i + width > n and not final:
            return keys, bytes(data[i:])
        ch = bytes(data[i:i + width]).decode("utf-8", errors="ignore")
        if ch and ch.isprintable():
            keys.append(ch.lower())
        i += width
    return keys, b""


# key sources -----------------------------------------------------------------------------------------
class KeySource:
    """Turns a keyboard into key names. ``poll()``: presses since the last poll, in order;
    ``held()``: keys held now; ``start()``/``stop()`` acquire and release the device."""

    name = "none"

    def start(self) -> None:
        """Acquire the device (idempotent)."""

    def stop(self) -> None:
        """Release the device and restore its state (idempotent)."""

    def poll(self) -> list[str]:
        return []

    def held(self) -> set[str]:
        return set()

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


class NullKeySource(KeySource):
    """No keyboard."""


class ScriptedKeySource(KeySource):
    """Replays ``events``: (when, key) pairs; ``when`` is a poll count (int, the n-th ``poll()``
    call, from 0) or, with ``clock``, a time in s since ``start()``. ``held()`` is always empty."""

    name = "scripted"

    def __init__(self, events: Iterable[tuple[float, str]], clock: Callable[[], float] | None = None):
        self.events = sorted(((float(w), str(k)) for w, k in events), key=lambda e: e[0])
        self._clock = clock
        self._polls = 0
        self._t0 = 0.0
        self._next = 0

    def start(self) -> None:
        self._t0 = self._clock() if self._clock else 0.0

    def poll(self) -> list[str]:
        now = (self._clock() - self._t0) if self._clock else float(self._polls)
        self._polls += 1
        out = []
        while self._next < len(self.events) and self.events[self._next][0] <= now:
            out.append(self.events[self._next][1])
            self._next += 1
        return out


class _EventBuffer:
    """Thread-safe buffer of presses plus the time each key was last seen (for ``held``)."""

    def __init__(self, clock: Callable[[], float]):
        self._lock = threading.Lock()
        self._events: list[str] = []
        self._down: set[str] = set()
        self._seen: dict[str, float] = {}
        self._clock = clock

    def press(self, key: str) -> None:
        with self._lock:
            self._events.append(key)
            self._down.add(key)
            self._seen[key] = self._clock()

    def release(self, key: str) -> None:
        with self._lock:
            self._down.discard(key)

    def drain(self) -> list[str]:
        with self._lock:
            out, self._events = self._events, []
        return out

    def down(self) -> set[str]:
        with self._lock:
            return set(self._down)

    def recent(self, within_s: float) -> set[str]:
        now = self._clock()
        with self._lock:
            return {k for k, t in self._seen.items() if now - t <= within_s}


def _pynput_name(key) -> str | None:
    char = getattr(key, "char", None)
    if char:
        return char.lower()
    name = getattr(key, "name", None)
    return name.lower() if isinstance(name, str) else None


class PynputKeySource(KeySource):
    """Global keyboard through ``pynput`` (true press/release, so ``held`` is exact)."""

    name = "pynput"

    def __init__(self, clock: Callable[[], float] = time.monotonic):
        self._buf = _EventBuffer(clock)
        self._listener = None

    def start(self) -> None:
        if self._listener is not None:
            return
        try:
            keyboard = importlib.import_module("pynput.keyboard")
        except ImportError as exc:
            raise ImportError("PynputKeySource needs the optional 'pynput' package (pip install pynput) and a display") from exc

        def on_press(key):
            name = _pynput_name(key)
            if name:
                self._buf.press(name)

        def on_release(key):
            name = _pynput_name(key)
            if name:
                self._buf.release(name)

        self._listener = keyboard.Listener(on_press=on_press, on_release=on_release)
        self._listener.start()

    def stop(self) -> None:
        if self._listener is not None:
            self._listener.stop()
            self._listener = None

    def poll(self) -> list[str]:
        return self._buf.drain()

    def held(self) -> set[str]:
        return self._buf.down()


class TerminalKeySource(KeySource):
    """The controlling terminal in cbreak mode, read by a background thread (see module doc).

    stream: a file object with ``fileno()`` (default ``sys.stdin``); it must be a TTY.
    hold_s: a key counts as held this long after its last press / auto-repeat.
    esc_wait_s: how long a trailing ESC waits for the rest of an escape sequence.
    """

    name = "terminal"

    def __init__(self, stream=None, *, hold_s: float = 0.12, esc_wait_s: float = 0.05,
                 clock: Callable[[], float] = time.monotonic):
        self._stream = stream if stream is not None else sys.stdin
        self.hold_s = float(hold_s)
        self.esc_wait_s = float(esc_wait_s)
        self._buf = _EventBuffer(clock)
        self._saved = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    @staticmethod
    def available(stream=None) -> bool:
        s = stream if stream is not None else sys.stdin
        try:
            import termios  # noqa: F401
            return os.isatty(s.fileno())
        except (ImportError, AttributeError, OSError, ValueError):
            return False

    def start(self) -> None:
        if self._thread is not None:
            return
        import termios
        import tty

        fd = self._stream.fileno()
        if not os.isatty(fd):
            raise RuntimeError("TerminalKeySource needs a terminal on stdin")
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)  # no echo, no line buffering; ISIG kept, so Ctrl-C still interrupts
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, args=(fd,), name="teleop-keys", daemon=True)
        self._thread.start()

    def _run(self, fd: int) -> None:
        import select

        tail = b""
        while not self._stop.is_set():
            ready, _, _ = select.select([fd], [], [], self.esc_wait_s if tail else 0.1)
            if ready:
                try:
                    chunk = os.read(fd, 64)
                except OSError:
                    return
                if not chunk:
                    return
                keys, tail = decode_terminal_keys(tail + chunk)
            else:
                keys, tail = decode_terminal_keys(tail, final=True) if tail else ([], b"")
            for k in keys:
                self._buf.press(k)

    def stop(self) -> None:
        if self._thread is None:
            return
        self._stop.set()
        self._thread.join(timeout=1.0)
        self._thread = None
        if self._saved is not None:
            import termios

            termios.tcsetattr(self._stream.fileno(), termios.TCSADRAIN, self._saved)
            self._saved = None

    def poll(self) -> list[str]:
        return self._buf.drain()

    def held(self) -> set[str]:
        return self._buf.recent(self.hold_s)


def _auto(**kw) -> KeySource:
    if importlib.util.find_spec("pynput") is not None and (os.environ.get("DISPLAY") or sys.platform in ("win32", "darwin")):
        return PynputKeySource(**kw)
    if TerminalKeySource.available():
        return TerminalKeySource(**kw)
    log.warning("no keyboard: pynput is not installed (or no display) and stdin is not a terminal; "
                "recording keys are off (stop with Ctrl-C)")
    return NullKeySource()


#: name -> factory; ``make_key_source`` looks names up here (one registry, no if/elif chains)
KEY_SOURCES: Mapping[str, Callable[..., KeySource]] = {
    "auto": _auto,
    "pynput": PynputKeySource,
    "terminal": TerminalKeySource,
    "none": lambda **kw: NullKeySource(),
}


def make_key_source(kind: str = "auto", **kwargs) -> KeySource:
    """A key source by name: one of ``KEY_SOURCES`` (auto, pynput, terminal, none)."""
    if kind not in KEY_SOURCES:
        raise ValueError(f"key source must be one of {sorted(KEY_SOURCES)}, got {kind!r}")
    return KEY_SOURCES[kind](**kwargs)
