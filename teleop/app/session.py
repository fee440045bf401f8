"""``CollectionSession``: the teleoperation loop that records demonstrations episode by episode.

Per control step while recording: poll the keys -> ``EpisodeControl`` -> effects; ``act(obs)`` of
the teleop device (device read, retargeting, IK); ``env.step``; ``send_feedback(info)`` (haptics);
live view and status line (throttled); then sleep to the control period (``realtime``). When a step
takes longer than the period the simulation runs slower than real time: the status line and the view
show ``BEHIND`` with the achieved rate, and the session says so once per episode (``late_steps`` in the
report counts such steps).

Each episode starts in a *waiting* state (``wait_for_devices``): nothing is stepped and the episode
clock stands still until the devices send usable data (``Controller.has_data``) or the operator
presses enter/space. A loss of device data during an episode (the agent holds the gripper) is
announced in the terminal, on the status line and on the page, and so is its return. During the
review the view keeps the last frame of the episode just finished and shows its result.

Recording goes through ``HDF5Recorder`` (``defgrasp_env.recording``), which writes each episode
atomically when it ends; the session adds the operator's success mark to every step's info
(``OperatorMarks`` -> ``info/operator_success`` in the file). Ending an episode resets the env at
once (so the recorder flushes it), then ``reset_time_s`` of review follow.

Ctrl-C: the first one asks the loop to stop after the current step (a finished episode that is being
written is never cut short); the episode in progress is then discarded explicitly (default) or kept
(``keep_interrupted``); a second Ctrl-C aborts at once (finished files are still intact: they are
only ever published complete).
"""

from __future__ import annotations

import logging
import pathlib
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import gymnasium as gym
import numpy as np

from .control import Effect, EpisodeControl, Phase
from .devices import Controller
from .keys import KeySource, NullKeySource, RecordCommand, commands_for_keys

log = logging.getLogger("teleop.app")


class SimClock:
    """Simulation time of the current episode (s): steps x dt (no summed rounding), 0 at reset."""

    def __init__(self):
        self.t = 0.0
        self.steps = 0

    def __call__(self) -> float:
        return self.t

    def advance(self, dt: float) -> None:
        self.steps += 1
        self.t = self.steps * dt

    def reset(self) -> None:
        self.t = 0.0
        self.steps = 0


class OperatorMarks(gym.Wrapper):
    """Adds ``info["operator_success"]`` (bool: the operator marked the episode a success with
    ``s``; set from that step on) to every step; ``HDF5Recorder`` stores it as
    ``info/operator_success``. Put it inside the recorder."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.success = False

    def reset(self, **kwargs):
        self.success = False
        return self.env.reset(**kwargs)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, {**info, "operator_success": bool(self.success)}


def make_env_stack(env_kwargs: dict, *, out_dir=None, render: bool = False, env_id: str = "DeformablePickup-v0",
                   say: Callable[[str], None] = print):
    """(outer env, recorder or None, OperatorMarks) for ``env_kwargs`` in absolute action mode.
    ``out_dir`` None: no recording. If ``defgrasp_env.recording`` is missing, says so and runs
    without recording."""
    import defgrasp_env  # noqa: F401  (registers the env)

    kwargs = {**env_kwargs, "action_mode": "absolute"}
    env = gym.make(env_id, render_mode="rgb_array" if render else None, **kwargs)
    marks = OperatorMarks(env)
    if out_dir is None:
        return marks, None, marks
    try:
        from defgrasp_env.recording import HDF5Recorder
    except ImportError as exc:
        say(f"WARNING: defgrasp_env.recording is not available ({exc}); running WITHOUT recording")
        return marks, None, marks
    rec = HDF5Recorder(marks, out_dir, policy="teleop")
    return rec, rec, marks


@dataclass(frozen=True)
class SessionConfig:
    """num_episodes to keep; reset_time_s of review between episodes; realtime: pace the loop at
    the control rate; view_hz / status_hz: live view and status line rates; seed: first reset
    seed (None: random), +1 per attempt unless fixed_seed; keep_interrupted: keep the episode in
    progress on Ctrl-C (default: discard it)."""

    num_episodes: int = 10
    reset_time_s: float = 2.0
    realtime: bool = True
    view_hz: float = 5.0
    status_hz: float = 1.0
    seed: int | None = None
    fixed_seed: bool = False
    keep_interrupted: bool = False
    wait_for_devices: bool = True

    def __post_init__(self):
        EpisodeControl(self.num_episodes, self.reset_time_s)  # validates both
        for name in ("view_hz", "status_hz"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not 0 <= v <= 1000:
                raise ValueError(f"{name} must be in [0, 1000] Hz, got {v!r}")
        if self.seed is not None and (isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0):
            raise ValueError(f"seed must be None or an int >= 0, got {self.seed!r}")


@dataclass
class SessionReport:
    """What a session did. saved: kept episode files in order; deleted: files removed by a
    re-record; discarded: episodes dropped unsaved; stopped_by: done / esc / interrupt / error."""

    saved: list = field(default_factory=list)
    deleted: list = field(default_factory=list)
    discarded: int = 0
    stopped_by: str = "done"
    steps: int = 0
    loop_hz: float | None = None
    step_time_s: dict = field(default_factory=dict)
    latency: dict = field(default_factory=dict)
    loop_rate_hz: dict = field(default_factory=dict)
    late_steps: int = 0
    data_losses: int = 0


class Console:
    """Messages and a one-line status on a stream: on a terminal the status line is redrawn in
    place and a message first clears it; elsewhere both are plain lines."""

    def __init__(self, stream=None, width: int = 160):
        self.stream = stream if stream is not None else sys.stdout
        self.width = width
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._status_shown = False

    def say(self, message: str) -> None:
        if self._status_shown:
            self.stream.write("\r\x1b[K")
            self._status_shown = False
        print(message, file=self.stream, flush=True)

    def status(self, line: str) -> None:
        if self.tty:
            self.stream.write("\r" + line[: self.width] + "\x1b[K")
            self.stream.flush()
            self._status_shown = True
        else:
            print(line, file=self.stream, flush=True)


class CollectionSession:
    """Runs the collection loop (module doc). ``env``: the outer env (the recorder if any);
    ``controller``: a ``Controller`` (or a bare TeleopDevice); ``marks``: the ``OperatorMarks``
    inside the recorder; ``view``: a live view or a list of them (``teleop.app.view``: objects with
    ``capture(env)``, ``update(frame, readouts)``, ``new_episode()``, ``close()``); ``sim_clock``: the
    clock replay devices run on."""

    def __init__(self, env: gym.Env, controller, keys: KeySource | None = None, *, recorder=None,
                 marks: OperatorMarks | None = None, view=None,
                 config: SessionConfig | None = None, sim_clock: SimClock | None = None,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 say: Callable[[str], None] | None = None, status: Callable[[str], None] | None = None,
                 handle_sigint: bool = True):
        self.env = env
        self.controller = controller if isinstance(controller, Controller) else Controller(controller, type(controller).__name__, True)
        self.device = self.controller.device
        self.keys = keys or NullKeySource()
        self.recorder, self.marks = recorder, marks
        self.views = [] if view is None else list(view) if isinstance(view, (list, tuple)) else [view]
        self.config = config or SessionConfig()
        self.sim_clock = sim_clock or SimClock()
        console = Console()
        self._clock, self._sleep = clock, sleep
        self._say, self._status = say or console.say, status or console.status
        self._handle_sigint = handle_sigint
        self.dt = float(env.unwrapped.config.dt)
        self.control = EpisodeControl(self.config.num_episodes, self.config.reset_time_s)
        self.report = SessionReport()
        self._interrupted = False
        self._attempt = 0
        self._steps = 0
        self._obs = None
        self._info: dict = {}
        self._step_times: list[float] = []
        self._last_view = self._last_status = -np.inf
        self._keep_current = False
        self._waiting = False
        self._device_state = "-"
        self._last_result: str | None = None
        self._tick_times: list[float] = []
        self._behind_said = False

    # signals -------------------------------------------------------------------------------------
    def _on_sigint(self, signum, frame) -> None:
        self._interrupted = True
        signal.signal(signal.SIGINT, signal.default_int_handler)  # a second Ctrl-C aborts at once
        self._say("Ctrl-C: stopping after this step (Ctrl-C again to abort now)")

    def request_stop(self) -> None:
        """Ask the loop to stop as on Ctrl-C (thread-safe)."""
        self._interrupted = True

    # episode handling ------------------------------------------------------------------------------
    def _next_seed(self) -> int | None:
        c = self.config
        seed = None if c.seed is None else c.seed + (0 if c.fixed_seed else self._attempt)
        self._attempt += 1
        return seed

    def _release_haptics(self) -> None:
        glove = self.controller.parts.get("glove")
        if glove is not None and glove.is_connected:
            glove.send_haptics(np.zeros(5), np.zeros(5), 0.0)

    def _reset_env(self, keep_pending: bool) -> None:
        """Reset for the next episode; the recorder saves the pending episode iff keep_pending, else
        discards it."""
        if self._steps:
            self._last_result = f"{'kept' if keep_pending else 'ended'}: {self._describe_last()}"
            self._publish(force=True, capture=True)  # the finished episode's last frame stays on the view
        if self.recorder is not None:
            if keep_pending:
                self.recorder.save("reset")
            else:
                self.recorder.discard()
        self._obs, _ = self.env.reset(seed=self._next_seed())
        self._collect_saved()
        self._info = {}
        self._steps = 0
        self.sim_clock.reset()
        self.device.reset()
        self._release_haptics()
        self._waiting = self.config.wait_for_devices
        self._behind_said = False
        self._device_state = "-"
        for view in self.views:
            view.new_episode()
        self._publish(force=True, capture=self.control.phase is not Phase.REVIEW)

    def _collect_saved(self) -> None:
        if self.recorder is None:
            return
        for p in self.recorder.paths[len(self.report.saved) + len(self.report.deleted):]:
            self.report.saved.append(pathlib.Path(p))
            self._say(f"saved {p} ({self._describe_last()})")

    def _describe_last(self) -> str:
        i = self._info
        return (f"{self._steps} steps ({self._steps * self.dt:.2f} s), success {bool(i.get('is_success', False))}, "
                f"operator mark {bool(i.get('operator_success', False))}"
                + (", diverged" if i.get("sim_diverged") else ""))

    def _apply(self, effect: Effect) -> None:
        c = self.control
        if effect is Effect.SAVE:
            if self.recorder is None:
                self._say(f"episode ended ({self._describe_last()}); not recorded")
            self._reset_env(keep_pending=True)
        elif effect is Effect.SAVED:
            self._collect_saved()
            if self.recorder is None:
                self._say(f"episode ended by the env ({self._describe_last()}); not recorded")
            self._reset_env(keep_pending=False)
        elif effect is Effect.DISCARD:
            if self._steps:
                self.report.discarded += 1
                self._say(f"discarded the episode ({self._steps} steps); recording it again")
            self._reset_env(keep_pending=False)
        elif effect is Effect.DELETE_LAST:
            if self.report.saved:
                p = self.report.saved.pop()
                p.unlink(missing_ok=True)
                self.report.deleted.append(p)
                self._say(f"deleted {p}; recording it again")
        elif effect is Effect.TOGGLE_SUCCESS:
            if self.marks is not None:
                self.marks.success = c.success_mark
            self._say(f"operator success mark: {'ON' if c.success_mark else 'off'}")
        elif effect is Effect.START:
            self.device.reset()
            self._waiting = self.config.wait_for_devices
            self._say(f"recording episode {c.kept + 1}/{c.num_episodes}"
                      + (": waiting for device data (enter/space starts now)" if self._waiting else ""))
            self._publish(force=True, capture=True)
        elif effect is Effect.GO:
            if self._waiting:
                self._waiting = False
                self._say("starting the episode now (start key)")
        elif effect is Effect.SAVE_AND_STOP:
            self._keep_current = True
        elif effect is Effect.STOP_INTERRUPTED:
            self._keep_current = self.config.keep_interrupted
        # Effect.STOP: nothing is pending; the loop ends and _finish closes everything

    # loop ----------------------------------------------------------------------------------------------
    def _step(self) -> bool:
        t0 = self._clock()
        action = self.device.act(self._obs)
        self._track_device_state()
        self._obs, _, terminated, truncated, info = self.env.step(action)
        self._info = info
        self.device.send_feedback(info)
        self.sim_clock.advance(self.dt)
        self._steps += 1
        self.report.steps += 1
        self._step_times.append(self._clock() - t0)
        self._publish()
        return bool(terminated or truncated)

    def _track_device_state(self) -> None:
        """Announce a loss of device data (the agent holds the gripper) and its return."""
        state, before = getattr(self.device, "status", "-"), self._device_state
        self._device_state = state
        if state == "hold" and before != "hold":
            self.report.data_losses += 1
            self._say(f"DEVICE DATA LOST at step {self._steps}: holding the gripper until data returns")
            self._publish(force=True)
        elif state != "hold" and before == "hold":
            self._say(f"device data back at step {self._steps}: continuing from the held pose")
            self._publish(force=True)

    def _headline(self) -> str:
        c = self.control
        if c.phase is Phase.REVIEW:
            return f"REVIEW - last episode {self._last_result or ''}"
        if c.phase is Phase.DONE:
            return "DONE"
        if self._waiting:
            return f"WAITING for device data (enter/space starts now) - episode {c.kept + 1}/{c.num_episodes}"
        if self._device_state == "hold":
            return "DEVICE DATA LOST - holding the gripper"
        return f"RECORDING episode {c.kept + 1}/{c.num_episodes}"

    def _readouts(self) -> dict:
        i, c = self._info, self.control
        lat = self.device.latency_stats() if self.controller.live_latency and hasattr(self.device, "latency_stats") else {}
        recent = np.diff(self._tick_times[-51:])
        recent = recent[recent < 10 * self.dt + 1.0]  # a wait or a review between two steps is no period
        hz = 1.0 / float(np.mean(recent)) if len(recent) else None
        return {
            "headline": self._headline(),
            "phase": "waiting" if (self._waiting and c.phase is Phase.RECORDING) else c.phase.value, "episode": min(c.kept + 1, c.num_episodes), "episodes_kept": c.kept,
            "episodes_wanted": c.num_episodes, "step": self._steps, "sim_time_s": round(self.sim_clock(), 3),
            "teleop_status": getattr(self.device, "status", "-"),
            "device_data": "-" if c.phase is not Phase.RECORDING else (
                "waiting" if self._waiting else "LOST" if self._device_state == "hold" else "ok"),
            "left_tip_force_N": i.get("left_tip_normal_force", 0.0), "right_tip_force_N": i.get("right_tip_normal_force", 0.0),
            "jaw_gap_mm": 1e3 * float(i.get("jaw_gap", np.nan)) if "jaw_gap" in i else None,
            "mean_von_mises_Pa": i.get("mean_von_mises"), "goal_distance_m": i.get("goal_distance"),
            "is_success": bool(i.get("is_success", False)), "operator_success": self.control.success_mark,
            "loop_hz": hz,
            "behind": bool(hz is not None and self.config.realtime and hz < 0.95 / self.dt
                           and c.phase is Phase.RECORDING and not self._waiting and self._steps > 1),
            "last_episode": self._last_result,
            "latency_p50_ms": 1e3 * lat["p50_s"] if lat.get("count") else None,
            "recording": str(self.recorder.directory) if self.recorder is not None else "off",
            "controller": self.controller.description,
        }

    def _publish(self, force: bool = False, capture: bool | None = None) -> None:
        """Views and status line (throttled unless ``force``); ``capture`` (default: not in review)
        draws the env's current state, else the views keep their frame and get new readouts."""
        now = self._clock()
        c = self.config
        capture = self.control.phase is not Phase.REVIEW if capture is None else capture
        if self.views and (force or (c.view_hz > 0 and now - self._last_view >= 1.0 / c.view_hz)):
            self._last_view = now
            readouts = self._readouts()
            for view in self.views:
                view.update(view.capture(self.env) if capture else None, readouts)
        if c.status_hz > 0 and (force or now - self._last_status >= 1.0 / c.status_hz):
            self._last_status = now
            r = self._readouts()
            lat = f"{r['latency_p50_ms']:.0f} ms" if r["latency_p50_ms"] is not None else "n/a"
            hz = f"{r['loop_hz']:.1f} Hz" if r["loop_hz"] else "- Hz"
            gap = f"{r['jaw_gap_mm']:.1f} mm" if r["jaw_gap_mm"] is not None else "-"
            stress = r["mean_von_mises_Pa"]
            self._status(f"[{r['phase']}] ep {r['episode']}/{r['episodes_wanted']} step {r['step']} | "
                         + ("DEVICE DATA LOST | " if r["device_data"] == "LOST" else "")
                         + ("BEHIND real time | " if r["behind"] else "") +
                         f"F L {r['left_tip_force_N']:.1f} N R {r['right_tip_force_N']:.1f} N | gap {gap} | "
                         f"stress {stress / 1e3 if stress is not None else float('nan'):.1f} kPa | "
                         f"{r['teleop_status']} | {hz} | latency {lat}"
                         + (" | SUCCESS" if r["is_success"] else "") + (" | marked" if r["operator_success"] else "")
                         + (f" | last episode {r['last_episode']}" if r["phase"] == "review" else ""))

    def run(self) -> SessionReport:
        """Run until enough episodes are kept, Esc, Ctrl-C or an error; returns the report."""
        install = self._handle_sigint and threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, self._on_sigint) if install else None
        c = self.control
        try:
            self.keys.start()
            self.device.connect()
            if self.recorder is None:
                self._say("WARNING: not recording (no output folder or no recorder)")
            self._reset_env(keep_pending=False)
            self._say(f"recording episode 1/{c.num_episodes} with {self.controller.description}; "
                      "keys: right arrow = end episode, left arrow = re-record, s = mark success, Esc = stop, "
                      "enter/space = start now"
                      + ("; waiting for device data" if self._waiting else ""))
            next_tick = self._clock()
            last = self._clock()
            while not c.done:
                effects = []
                if self._interrupted:
                    effects = c.interrupt()
                    self.report.stopped_by = "interrupt"
                else:
                    for cmd in commands_for_keys(self.keys.poll()):
                        effects += c.command(cmd, self._steps)
                        if cmd is RecordCommand.STOP:
                            self.report.stopped_by = "esc"
                for e in effects:
                    self._apply(e)
                if c.done:
                    break
                now = self._clock()
                if c.phase is Phase.RECORDING and self._waiting:
                    if self.controller.has_data():
                        self._waiting = False
                        self._say("device data arrived: episode started")
                    else:
                        self._publish()
                        if not self.config.realtime:
                            self._sleep(0.005)
                if c.phase is Phase.RECORDING and not self._waiting:
                    self._tick_times.append(now)
                    if self._step():
                        for e in c.episode_ended(self._steps):
                            self._apply(e)
                else:
                    for e in c.review_tick(now - last):
                        self._apply(e)
                    self._publish()
                last = now
                if self.config.realtime:
                    next_tick += self.dt
                    wait = next_tick - self._clock()
                    if wait > 0:
                        self._sleep(wait)
                    elif wait < -self.dt:  # behind: do not try to catch up with a burst
                        next_tick = self._clock()
                        self._fell_behind()
        except BaseException as exc:
            self.report.stopped_by = "interrupt" if isinstance(exc, KeyboardInterrupt) else "error"
            self._keep_current = False
            raise
        finally:
            self._finish(previous, install)
        return self.report

    def _fell_behind(self) -> None:
        """A step ended more than one period late: count it; say it once per episode."""
        self.report.late_steps += 1
        if not self._behind_said and self.control.phase is Phase.RECORDING and not self._waiting:
            self._behind_said = True
            recent = np.diff(self._tick_times[-21:])
            hz = f"{1.0 / float(np.mean(recent)):.1f} Hz" if len(recent) else "?"
            self._say(f"BEHIND real time: the loop runs at {hz}, below the {1.0 / self.dt:.0f} Hz control rate "
                      "(the simulation runs slower than the clock)")

    def _finish(self, previous_handler, installed: bool) -> None:
        steps = self._steps
        for what, fn in (("keys", self.keys.stop), ("haptics", self._release_haptics), ("env", lambda: self._close_env(steps)),
                         ("device", self.device.disconnect), *(("view", v.close) for v in self.views)):
            try:
                fn()
            except Exception:  # keep cleaning up; the failure is reported, not swallowed
                log.exception("closing the %s failed", what)
        if installed:
            signal.signal(signal.SIGINT, previous_handler)
        st = self._step_times[3:] or self._step_times
        if st:
            a = np.array(st)
            self.report.loop_hz = float(1.0 / a.mean())
            self.report.step_time_s = {"p50": float(np.median(a)), "p95": float(np.percentile(a, 95))}
        periods = np.diff(self._tick_times)
        periods = periods[periods < 10 * self.dt + 1.0]  # a review or a wait between episodes is no period
        if len(periods) > 3:
            rates = 1.0 / periods[3:] if len(periods) > 6 else 1.0 / periods
            # p95: the rate that 95 % of the loop periods reach (1 / the 95th percentile of the period)
            self.report.loop_rate_hz = {"p50": float(np.median(rates)), "p95": float(np.percentile(rates, 5))}
        if self.controller.live_latency and hasattr(self.device, "latency_stats"):
            self.report.latency = self.device.latency_stats()
        self._say(f"stopped ({self.report.stopped_by}): {len(self.report.saved)} episode(s) kept"
                  + (f" in {self.recorder.directory}" if self.recorder is not None else ""))

    def _close_env(self, steps: int) -> None:
        if self.recorder is not None:
            if self._keep_current:
                self.recorder.save("close")
            else:
                self.recorder.discard()
            if steps and not self._keep_current:
                self.report.discarded += 1
                self._say(f"discarded the unfinished episode ({steps} steps)")
        self.env.close()
        self._collect_saved()
