"""Play recorded tracker/glove streams into the UDP receivers, as a glove/tracker bridge would.

``StreamPlayer`` sends each recorded sample through the reference senders (``UdpTrackerSender``,
``UdpGloveSender``) when its stream time (seconds from the first sample) has come, stamped with the
sender's clock at sending, and collects the ``glove_haptics`` datagrams sent back. Two ways to drive
it:

* ``advance_to(t)`` (lock-step): the caller says what stream time it is, e.g. the simulation time
  of the control step about to run; the end-to-end test and the benchmark use this, so a replay is
  as fast as the loop runs yet each control step sees exactly the samples an operator would have
  produced by then;
* ``run_realtime`` / the CLI: stream time = wall time since start (optionally looped), for trying
  ``defgrasp-teleop --tracker udp --glove udp`` without hardware:

      python -m teleop.testing.udp_replay --tracker tests/data/human_pick_cuboid_tracker.jsonl \\
          --glove tests/data/human_pick_cuboid_glove.jsonl
"""

from __future__ import annotations

import argparse
import collections
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..sensors.base import GloveSample, TrackerSample
from ..sensors.recorder import load_stream
from ..sensors.udp_glove import DEFAULT_GLOVE_PORT, HapticsCommand, UdpGloveSender
from ..sensors.udp_tracker import DEFAULT_TRACKER_PORT, UdpTrackerSender

#: entries kept in ``StreamPlayer.sent_log`` and ``.haptics`` (the newest)
LOG_LENGTH = 200_000


@dataclass(frozen=True)
class ReceivedHaptics:
    """A haptics command as the bridge got it: the command and the host time it was read (s)."""

    command: HapticsCommand
    t_received_s: float


def _samples(source, kind: str) -> tuple:
    if isinstance(source, (list, tuple)):
        return tuple(source)
    stream = load_stream(source)
    if stream.kind != kind:
        raise ValueError(f"{source} holds a {stream.kind} stream, expected {kind}")
    return stream.samples


class StreamPlayer:
    """Sends recorded samples to ``tracker_address`` / ``glove_address`` (module doc).

    tracker, glove: a stream file path or a sequence of ``TrackerSample`` / ``GloveSample`` (either
    may be None). ``sent_log``: (kind, sequence, host send time) per datagram; ``haptics``: every
    ``ReceivedHaptics`` collected by ``poll_haptics`` (both keep the newest ``LOG_LENGTH``).
    """

    def __init__(self, tracker=None, glove=None, *, tracker_address: tuple[str, int] | None = None,
                 glove_address: tuple[str, int] | None = None, clock: Callable[[], float] = time.monotonic):
        if tracker is None and glove is None:
            raise ValueError("StreamPlayer needs a tracker stream, a glove stream or both, got neither")
        self._clock = clock
        self.tracker = _samples(tracker, "tracker") if tracker is not None else ()
        self.glove = _samples(glove, "glove") if glove is not None else ()
        for kind, s, cls in (("tracker", self.tracker, TrackerSample), ("glove", self.glove, GloveSample)):
            if not all(isinstance(x, cls) for x in s):
                raise TypeError(f"the {kind} stream must hold {cls.__name__} samples")
        if self.tracker and tracker_address is None or self.glove and glove_address is None:
            raise ValueError("each stream given needs its receiver address (tracker_address / glove_address)")
        t0 = min(s[0].timestamp_s for s in (self.tracker, self.glove) if s)
        self._t_tracker = np.array([x.timestamp_s - t0 for x in self.tracker])
        self._t_glove = np.array([x.timestamp_s - t0 for x in self.glove])
        self.duration_s = float(max(self._t_tracker.max(initial=0.0), self._t_glove.max(initial=0.0)))
        self._tx_tracker = UdpTrackerSender(tracker_address, clock=clock) if self.tracker else None
        self._tx_glove = UdpGloveSender(glove_address, clock=clock) if self.glove else None
        self.sent_log: collections.deque = collections.deque(maxlen=LOG_LENGTH)
        self.haptics: collections.deque = collections.deque(maxlen=LOG_LENGTH)
        self.rewind()

    def rewind(self) -> None:
        """Start again from the first sample."""
        self._i_tracker = self._i_glove = 0

    @property
    def finished(self) -> bool:
        return self._i_tracker >= len(self.tracker) and self._i_glove >= len(self.glove)

    def advance_to(self, t: float) -> int:
        """Send every sample with stream time <= ``t`` (s) not sent yet; returns how many."""
        n = 0
        while self._i_tracker < len(self.tracker) and self._t_tracker[self._i_tracker] <= t:
            s = self.tracker[self._i_tracker]
            t_send = self._clock()
            seq = self._tx_tracker.send(s.pose, valid=s.valid, connected=True, timestamp_s=t_send)
            self.sent_log.append(("tracker", seq, t_send))
            self._i_tracker += 1
            n += 1
        while self._i_glove < len(self.glove) and self._t_glove[self._i_glove] <= t:
            s = self.glove[self._i_glove]
            t_send = self._clock()
            seq = self._tx_glove.send(s.joint_angles, s.fingertip_positions, connected=s.connected, timestamp_s=t_send)
            self.sent_log.append(("glove", seq, t_send))
            self._i_glove += 1
            n += 1
        return n

    def poll_haptics(self) -> HapticsCommand | None:
        """Collect the haptics commands sent back since the last poll; returns the newest or None."""
        if self._tx_glove is None:
            return None
        cmd = self._tx_glove.poll_haptics()
        if cmd is not None:
            self.haptics.append(ReceivedHaptics(cmd, self._clock()))
        return cmd

    def close(self) -> None:
        for tx in (self._tx_tracker, self._tx_glove):
            if tx is not None:
                tx.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def run_realtime(player: StreamPlayer, *, loop: bool = False, speed: float = 1.0, period_s: float = 0.002,
                 on_haptics: Callable[[HapticsCommand], None] | None = None,
                 should_stop: Callable[[], bool] = lambda: False, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
    """Stream in real time (stream time = ``speed`` x wall time since start) until the end of the
    streams (or forever with ``loop``) or ``should_stop()``."""
    start = clock()
    while not should_stop():
        t = (clock() - start) * speed
        player.advance_to(t)
        cmd = player.poll_haptics()
        if cmd is not None and on_haptics is not None:
            on_haptics(cmd)
        if player.finished:
            if not loop:
                return
            player.rewind()
            start = clock()
        sleep(period_s)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m teleop.testing.udp_replay",
                                description="Stream recorded tracker/glove files to defgrasp's UDP receivers in real time.")
    p.add_argument("--tracker", help="tracker stream (.jsonl/.npz)")
    p.add_argument("--glove", help="glove stream (.jsonl/.npz)")
    p.add_argument("--host", default="127.0.0.1", help="receiver host (default 127.0.0.1)")
    p.add_argument("--tracker-port", type=int, default=DEFAULT_TRACKER_PORT)
    p.add_argument("--glove-port", type=int, default=DEFAULT_GLOVE_PORT)
    p.add_argument("--loop", action="store_true", help="start again at the end")
    p.add_argument("--speed", type=float, default=1.0, help="playback speed factor (default 1)")
    args = p.parse_args(argv)
    if args.tracker is None and args.glove is None:
        p.error("give --tracker, --glove or both")
    player = StreamPlayer(args.tracker, args.glove, tracker_address=(args.host, args.tracker_port),
                          glove_address=(args.host, args.glove_port))
    last = [0.0]

    def show(cmd: HapticsCommand) -> None:
        now = time.monotonic()
        if now - last[0] > 0.5:
            last[0] = now
            print(f"haptics: force feedback {np.round(cmd.force_feedback, 2).tolist()} "
                  f"vibration {np.round(cmd.vibration, 2).tolist()} ({cmd.vibration_duration_s:.2f} s)")

    print(f"streaming {player.duration_s:.1f} s{' in a loop' if args.loop else ''}; Ctrl-C stops")
    try:
        run_realtime(player, loop=args.loop, speed=args.speed, on_haptics=show)
    except KeyboardInterrupt:
        pass
    finally:
        player.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
