"""Episode flow of a collection session as a pure state machine (no env, no files, no clock).

Phases: ``RECORDING`` (the env is stepped and recorded), ``REVIEW`` (between episodes, for
``reset_time_s``: the scene is already reset, the operator re-centres; the episode just saved can
still be thrown away), ``DONE``.

Inputs -> effects (``Effect``, executed in order by the session):

=============  =============================================  ==========================================
input          RECORDING                                      REVIEW
=============  =============================================  ==========================================
right arrow    SAVE (keep, reset) -> REVIEW                   START (end the review early)
left arrow     DISCARD (drop, reset), record again            DELETE_LAST (remove its file), START again
s              TOGGLE_SUCCESS (operator's success mark)       ignored (the episode is already written)
Esc            SAVE_AND_STOP (keep it, like LeRobot) -> DONE  STOP -> DONE
enter / space  GO (start now, without waiting for devices)    START, GO (end the review, start now)
env ended      SAVED (the recorder wrote it; reset) -> REVIEW -
review timeout -                                              START (or STOP once enough are kept)
interrupt      STOP_INTERRUPTED -> DONE                       STOP -> DONE
=============  =============================================  ==========================================

An episode without any step is neither saved nor counted.
"""

from __future__ import annotations

import enum

from .keys import RecordCommand


class Phase(enum.Enum):
    RECORDING = "recording"
    REVIEW = "review"
    DONE = "done"


class Effect(enum.Enum):
    SAVE = "save"  # keep the current episode (write it) and reset the env
    SAVED = "saved"  # the recorder wrote it already (terminated / truncated); reset the env
    DISCARD = "discard"  # drop the current episode and reset the env
    DELETE_LAST = "delete_last"  # remove the last saved episode file
    TOGGLE_SUCCESS = "toggle_success"
    START = "start"  # begin recording the (already reset) next episode
    SAVE_AND_STOP = "save_and_stop"  # close, keeping the current episode
    STOP = "stop"  # close; nothing unsaved is pending
    STOP_INTERRUPTED = "stop_interrupted"  # close after Ctrl-C: the session's policy decides
    GO = "go"  # start stepping now even if the devices have sent no data yet


class EpisodeControl:
    """State of the episode flow (module doc). ``kept``: episodes saved and not deleted."""

    def __init__(self, num_episodes: int, reset_time_s: float):
        if isinstance(num_episodes, bool) or not isinstance(num_episodes, int) or num_episodes < 1:
            raise ValueError(f"num_episodes must be an int in [1, inf), got {num_episodes!r}")
        if not isinstance(reset_time_s, (int, float)) or not 0 <= reset_time_s < 3600:
            raise ValueError(f"reset_time_s must be in [0, 3600) s, got {reset_time_s!r}")
        self.num_episodes = num_episodes
        self.reset_time_s = float(reset_time_s)
        self.phase = Phase.RECORDING
        self.kept = 0
        self.success_mark = False
        self._review_left_s = 0.0

    @property
    def done(self) -> bool:
        return self.phase is Phase.DONE

    def _end_episode(self, effect: Effect, steps: int) -> list[Effect]:
        self.success_mark = False
        if steps == 0:  # nothing recorded: nothing to keep or review
            return [Effect.DISCARD]
        self.kept += 1
        self.phase = Phase.REVIEW
        self._review_left_s = self.reset_time_s
        return [effect]

    def command(self, cmd: RecordCommand, steps: int) -> list[Effect]:
        """Effects of an operator command; ``steps``: steps recorded in the current episode."""
        if not isinstance(cmd, RecordCommand):
            raise TypeError(f"cmd must be a RecordCommand, got {cmd!r}")
        if self.phase is Phase.DONE:
            return []
        if self.phase is Phase.RECORDING:
            if cmd is RecordCommand.END_EPISODE:
                return self._end_episode(Effect.SAVE, steps)
            if cmd is RecordCommand.RERECORD:
                self.success_mark = False
                return [Effect.DISCARD]
            if cmd is RecordCommand.MARK_SUCCESS:
                self.success_mark = not self.success_mark
                return [Effect.TOGGLE_SUCCESS]
            if cmd is RecordCommand.START_NOW:
                return [Effect.GO]
            self.phase = Phase.DONE
            if steps:
                self.kept += 1
            return [Effect.SAVE_AND_STOP]
        # REVIEW
        if cmd is RecordCommand.END_EPISODE:
            return self._start()
        if cmd is RecordCommand.RERECORD:
            self.kept -= 1
            self.phase = Phase.RECORDING
            return [Effect.DELETE_LAST, Effect.START]
        if cmd is RecordCommand.MARK_SUCCESS:
            return []
        if cmd is RecordCommand.START_NOW:
            effects = self._start()
            return effects + [Effect.GO] if self.phase is Phase.RECORDING else effects
        self.phase = Phase.DONE
        return [Effect.STOP]

    def episode_ended(self, steps: int) -> list[Effect]:
        """The env terminated or truncated (the recorder has written the episode)."""
        if self.phase is not Phase.RECORDING:
            raise RuntimeError(f"episode_ended() while {self.phase.value}")
        return self._end_episode(Effect.SAVED, steps)

    def review_tick(self, elapsed_s: float) -> list[Effect]:
        """Time passing in REVIEW; START (or STOP when enough are kept) once the review is over."""
        if self.phase is not Phase.REVIEW:
            return []
        self._review_left_s -= float(elapsed_s)
        return self._start() if self._review_left_s <= 0 else []

    def _start(self) -> list[Effect]:
        if self.kept >= self.num_episodes:
            self.phase = Phase.DONE
            return [Effect.STOP]
        self.phase = Phase.RECORDING
        return [Effect.START]

    def interrupt(self) -> list[Effect]:
        """Ctrl-C: stop; an episode being recorded is handled by the session's policy."""
        if self.phase is Phase.DONE:
            return []
        was = self.phase
        self.phase = Phase.DONE
        return [Effect.STOP_INTERRUPTED] if was is Phase.RECORDING else [Effect.STOP]
