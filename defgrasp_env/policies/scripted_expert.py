"""``ScriptedPickupExpert``: a phase-scripted top-down pick-up policy from observations only.

It reads nothing but the observation dict of ``DeformablePickup-v0`` (``obs_type="state"``), in
the layout of ``defgrasp_env.layout``, and the public gripper geometry of ``defgrasp_env.gripper``;
it never touches the simulator. Works on one observation (``agent_pos`` [10], ``environment_state``
[33]) or a batch ([N, 10], [N, 33], as from ``gym.make_vec``) and returns float32 delta actions
(``DELTA_ACTION``) [7] or [N, 7], or, for an env with ``action_mode="absolute"``, absolute actions
(``ABSOLUTE_ACTION``) [8] or [N, 8]: the flange position one control period ahead on the same
(speed- and acceleration-limited) path, the orientation it is turning to (the planned grasp yaw,
held for the whole turn: the env turns toward it at ``max_angular_speed``, as the delta action's
saturated rate does) and the jaw gap command (leading the gap by ``absolute_close_lead``
periods of its closing rate while it closes slowly or squeezes; ``delta_close_lead`` in delta and top-down
actions, 1 by default). Both move the wrist alike: the
expert's velocity is limited in norm to ``max_linear_speed``, which is what an absolute move
allows (a delta action limits each component, so other delta policies may move diagonally up to
sqrt 3 faster). For an env with ``action_mode="topdown"`` it returns ``TOPDOWN_ACTION`` [5] or
[N, 5]: the delta action's velocities and jaw command with the planned yaw (rad) in place of the
angular velocity.

Phases (per world, explicit state; ``reset()`` restarts them):

0. ``APPROACH``: plan the grasp from the keypoints (``grasp_planning``), turn the wrist so that the
   closing axis spans the object's narrowest horizontal extent, move the tool centre point (tcp,
   pad-centre midpoint) above the grasp point and preset the jaw gap.
1. ``DESCEND``: lower the tcp to the grasp height (pads straddling the feature point at
   mid-height, pad bottoms kept above the ground), plan frozen.
2. ``CLOSE``: close fast to a few mm outside the estimated width, then at 20 mm/s until a pad
   touches and on until both tip forces reach ``grip_force`` (or the gap stops shrinking, e.g. at
   the gripper's own force limit). The flange rises as the closing fingers swing down, so the pads
   stay at the grasp height. Because the tip-force readings carry one- or two-step spikes of
   10-1000 N (unconverged contact solves), "enough grip" is judged on each pad's minimum over the
   last ``force_window`` steps. From then on the jaw command stays at least ``grip_overtravel``
   inside the gap at first contact, so that a stiff object (squeezed less than that at
   ``grip_force``) is held by the gripper's own force limit, as a real position-commanded 2F-85
   holds what it closes on; an object that squeezes more than that at ``grip_force`` (E = 1e4) is
   held as before, E = 1e5 ones at 4-9 N. The reference is the gap at first touch (a pad above
   ``contact_force``), which can be ~3 mm wider than the object: the command then ends ~1 mm
   inside the held gap of a stiff cube.
3. ``LIFT``: move the tcp so that the feature point goes to the goal (speed-, acceleration- and
   braking-limited; hangs and sags are taken out through a filtered tcp-to-feature offset) and
   hold it there; the grip is re-tightened slowly while a (filtered) tip force is below
   ``regrip_fraction * grip_force``, down to ``regrip_floor`` times the gap at first contact.
4. ``RETREAT``: the grasp was lost (both forces ~0, or the jaws closed on nothing): open, rise,
   and go back to ``APPROACH`` (at most ``max_retries`` times, then keep holding still).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ..gripper import tcp_offset
from ..layout import (ABSOLUTE_ACTION, AGENT_POS, DELTA_ACTION, ENV_STATE, JAW_GAP_MAX, JAW_GAP_MIN,
                      NUM_KEYPOINTS, TOPDOWN_ACTION, gap_to_jaw_command)
from .grasp_planning import PAD_HALF_LENGTH, plan_grasps

__all__ = ["ExpertConfig", "ScriptedPickupExpert", "PHASE_NAMES", "RECOMMENDED_ENV_KWARGS"]

APPROACH, DESCEND, CLOSE, LIFT, RETREAT = range(5)
PHASE_NAMES = ("approach", "descend", "close", "lift", "retreat")

#: Env options the expert is benchmarked with: the env's defaults (see benchmarks/RESULTS.md).
RECOMMENDED_ENV_KWARGS: dict = {}


@dataclass(frozen=True)
class ExpertConfig:
    """Tuning of the scripted expert (SI units; validated).

    ``max_linear_speed``, ``max_angular_speed`` and ``control_hz`` must equal the env's
    ``PickupConfig`` values (they scale the normalised delta and top-down actions and an absolute
    action's one-period move); use
    ``ScriptedPickupExpert.from_env(env)`` to copy them.
    """

    max_linear_speed: float = 0.3        # m/s, env's action scale
    max_angular_speed: float = 1.5       # rad/s, env's action scale
    control_hz: float = 20.0             # Hz, env's control rate
    # N, target normal force on each pad. Far below the 20 N force limit on purpose: the objects
    # weigh ~0.3 N (pad friction 1.0), and at E = 1e4 Pa even 1.5 N squeezes a 16 mm rope to ~9 mm;
    # 5 N crushes it flat (gap -> 1.5 mm) and makes the contact solve blow up. The success test
    # needs > 0.5 N on both pads, hence 1.5 N with re-gripping below 0.8 N.
    grip_force: float = 1.5
    contact_force: float = 0.2           # N, a pad counts as touching above this
    regrip_fraction: float = 0.55        # re-squeeze in LIFT below this fraction of grip_force ...
    regrip_floor: float = 0.3            # ... but never below this fraction of the gap at first contact
    # m, once gripped the jaw command stays at least this far inside the gap at first contact: a
    # stiff object (E >= 1e6 squeezes < 0.1 mm at grip_force) is then held at the jaw driver's grip
    # force limit (20 N by default) instead of at a gap it must match to a fraction of a mm; a
    # policy that imitates the expert (with mm-scale errors in its jaw command) keeps its grasp
    # (ACT on 100 demonstrations: 0/10 stiff cuboids and cylinders with the exact-gap commands).
    # Objects that squeeze more than this at grip_force (E = 1e4) are unaffected; E = 1e5 ones are
    # held at 4-9 N. First touch can be ~3 mm wider than the object (40.2 mm cube touched at 43.2 mm),
    # so on a stiff cube the command sits only ~1 mm inside the held gap.
    grip_overtravel: float = 0.004
    lost_force: float = 0.05             # N, both forces below this for lost_steps = grasp lost
    lost_steps: int = 4
    approach_margin: float = 0.008       # m, fast closing stops this far outside the estimate
    slow_close_speed: float = 0.02       # m/s, closing speed from there to the contact
    squeeze_speed: float = 0.02          # m/s, closing speed while squeezing to grip_force
    # control periods by which the jaw command of the slow close and the squeeze leads the current
    # gap in absolute actions (delta and top-down actions, whose jaw command is the same: 1 period,
    # the rate above; ACT on delta demonstrations did not stall on it). A command one period
    # (1 mm) inside the gap is within a learner's regression error of the gap it observes: ACT
    # trained on such absolute demonstrations commanded the gap it saw and stalled on the soft rope
    # and torus at 0.2 N (benchmarks/RESULTS.md, 2026-11-26); 3 periods close 3 mm a step there.
    # Near the jaw's minimum the command may fall below 0; the absolute action clips it to 0 (shut).
    # The lift's slow re-grip (0.5 mm a step) is not led.
    absolute_close_lead: int = 3
    # the same lead in delta and top-down actions (their jaw command is a gap too): 1 by default (the
    # rate above). A policy cloned from the expert into PPO's network (an MLP on one observation)
    # learnt to command about the gap it saw and stalled 2 mm above the stiff rope with 1 period
    # (benchmarks/RESULTS.md, 2026-12-06); ``ExpertClone`` collects with 3.
    delta_close_lead: int = 1
    hover_clearance: float = 0.02        # m, pad bottoms above the object's top before descending
    descend_speed: float = 0.2           # m/s
    lift_speed: float = 0.25             # m/s
    lift_acceleration: float = 1.5       # m/s^2
    offset_filter: float = 0.2           # EMA weight of the newest tcp->feature offset
    position_tolerance: float = 0.003    # m, phase switches
    yaw_tolerance: float = 0.03          # rad
    settle_steps: int = 1                # steps with both filtered forces >= grip_force before lifting
    force_window: int = 3                # steps: decisions use each pad's minimum over this window
    max_retries: int = 2

    def __post_init__(self) -> None:
        for name in ("absolute_close_lead", "delta_close_lead"):
            lead = getattr(self, name)
            if isinstance(lead, bool) or not isinstance(lead, int) or lead < 1:
                raise ValueError(f"{name} must be an integer >= 1 (control periods), got {lead!r}")
        for f in fields(self):
            v = getattr(self, f.name)
            if f.type in ("int", int):
                if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                    raise ValueError(f"{f.name} must be an integer >= 0, got {v!r}")
            else:
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                    raise ValueError(f"{f.name} must be a finite number in (0, inf), got {v!r}")
        if not self.regrip_fraction < 1.0 or not self.offset_filter <= 1.0:
            raise ValueError(f"regrip_fraction must be in (0, 1) and offset_filter in (0, 1], got "
                             f"{self.regrip_fraction}, {self.offset_filter}")

    @property
    def dt(self) -> float:
        return 1.0 / self.control_hz


def _quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate v [N, 3] by unit quaternions q [N, 4] (xyzw)."""
    u, w = q[:, :3], q[:, 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _yaw_quat(yaw: np.ndarray) -> np.ndarray:
    """Top-down flange orientation: rotation by ``yaw`` about world +y, xyzw [N, 4]."""
    z = np.zeros_like(yaw)
    return np.stack([z, np.sin(yaw / 2), z, np.cos(yaw / 2)], axis=1)


def _rotation_vector(q_target: np.ndarray, q: np.ndarray) -> np.ndarray:
    """World-frame rotation vector [N, 3] (rad) taking orientation q to q_target (both xyzw)."""
    # r = q_target * conj(q)
    x1, y1, z1, w1 = q_target.T
    x2, y2, z2, w2 = (-q[:, 0], -q[:, 1], -q[:, 2], q[:, 3])
    r = np.stack([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                  w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                  w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
                  w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2], axis=1)
    r = np.where(r[:, 3:4] < 0, -r, r)
    s = np.linalg.norm(r[:, :3], axis=1)
    angle = 2.0 * np.arctan2(s, r[:, 3])
    return r[:, :3] * np.where(s > 1e-12, angle / np.maximum(s, 1e-12), 2.0)[:, None]


@dataclass(frozen=True)
class WristCommand:
    """One control period's command of the expert, per world: ``flange`` [N, 3] (m, world, where it
    is), ``linear`` [N, 3] and ``angular`` [N, 3] (velocities in units of the env's speed limits,
    components in [-1, 1]), ``target_yaw`` [N] (rad about world +y from flange-down: the orientation
    it turns to) and ``gap`` [N] (m, the jaw gap command)."""

    flange: np.ndarray
    linear: np.ndarray
    angular: np.ndarray
    target_yaw: np.ndarray
    gap: np.ndarray


def delta_action(command: WristCommand, config: ExpertConfig) -> np.ndarray:
    """``DELTA_ACTION`` [N, 7]: the velocities and the jaw command of the gap."""
    action = DELTA_ACTION.pack(linear_velocity=command.linear, angular_velocity=command.angular,
                               jaw=gap_to_jaw_command(command.gap)[:, None])
    return np.clip(action, -1.0, 1.0)


def absolute_action(command: WristCommand, config: ExpertConfig) -> np.ndarray:
    """``ABSOLUTE_ACTION`` [N, 8]: the flange position one period ahead at the commanded velocity,
    the orientation turned to, and the gap."""
    low, high = ABSOLUTE_ACTION.field("position").bounds()
    position = np.clip(command.flange + command.linear * config.max_linear_speed * config.dt, low, high)
    gap = np.clip(command.gap, 0.0, JAW_GAP_MAX)[:, None]
    return ABSOLUTE_ACTION.pack(position=position, orientation=_yaw_quat(command.target_yaw), gap=gap)


def topdown_action(command: WristCommand, config: ExpertConfig) -> np.ndarray:
    """``TOPDOWN_ACTION`` [N, 5]: the velocities (as ``delta_action``), the yaw (rad, about world +y,
    in [-pi, pi]) of the orientation turned to, and the jaw command of the gap."""
    yaw = (command.target_yaw + np.pi) % (2.0 * np.pi) - np.pi  # the plan may reach +-3 pi / 2
    action = TOPDOWN_ACTION.pack(linear_velocity=command.linear, yaw=yaw[:, None],
                                 jaw=gap_to_jaw_command(command.gap)[:, None])
    low, high = TOPDOWN_ACTION.bounds()
    return np.clip(action, low, high)


#: The action each env ``action_mode`` takes, from the expert's command.
ACTION_PACKERS = {"delta": delta_action, "absolute": absolute_action, "topdown": topdown_action}


class ScriptedPickupExpert:
    """Scripted pick-up expert for ``DeformablePickup-v0`` (delta, absolute or top-down actions, state
    observations).

    ``expert(obs) -> action``: ``obs`` is the env's observation dict with ``agent_pos`` [10] or
    [N, 10] (flange position m, quaternion xyzw, jaw gap m, left/right tip normal force N) and
    ``environment_state`` [33] or [N, 33] (feature point m, its velocity m/s, goal m, 8 keypoints
    m, all world frame, y up). Returns float32 [7] or [N, 7] in [-1, 1] (``action_mode="delta"``):
    flange linear velocity, angular velocity (world axis-angle rate), jaw command; or [8] or [N, 8]
    (``"absolute"``): target flange position m, orientation xyzw, jaw gap m; or [5] or [N, 5]
    (``"topdown"``): the delta linear velocity, the target yaw rad, the jaw command. ``from_env``
    takes the mode from the env's config. Call ``reset()`` at every episode start
    (``reset(mask)`` for the worlds of a vector env that were reset).

    ``phase`` [N] (int, see ``PHASE_NAMES``) and ``retries`` [N] expose the script's state.
    """

    def __init__(self, config: ExpertConfig | None = None, *, action_mode: str = "delta", **overrides):
        if action_mode not in ACTION_PACKERS:
            raise ValueError(f"action_mode must be one of {sorted(ACTION_PACKERS)}, got {action_mode!r}")
        #: the env's ``action_mode`` the actions are for (``"delta"``, ``"absolute"`` or ``"topdown"``)
        self.action_mode = action_mode
        base = config if config is not None else ExpertConfig()
        if not isinstance(base, ExpertConfig):
            raise TypeError(f"config must be an ExpertConfig, got {type(base).__name__}")
        self.config = ExpertConfig(**{**{f.name: getattr(base, f.name) for f in fields(base)}, **overrides})
        self.num_worlds = 0
        self._alloc(0)

    @classmethod
    def from_env(cls, env, **overrides) -> ScriptedPickupExpert:
        """Expert whose action scaling matches ``env``'s public ``PickupConfig`` (single or vector
        env, wrapped or not). Only the configuration is read, never the simulation."""
        cfg = getattr(env.unwrapped, "config", None)
        if cfg is None:
            raise TypeError(f"{type(env).__name__} has no PickupConfig in .unwrapped.config")
        if "action_mode" in overrides:
            raise ValueError(f"action_mode comes from the env's config ({cfg.action_mode!r}); got "
                             f"action_mode={overrides['action_mode']!r} as well")
        if cfg.action_mode not in ACTION_PACKERS or cfg.obs_type != "state":
            raise ValueError(f"the expert needs action_mode in {sorted(ACTION_PACKERS)} and obs_type='state', got "
                             f"{cfg.action_mode!r}, {cfg.obs_type!r}")
        kw = dict(max_linear_speed=cfg.max_linear_speed, max_angular_speed=cfg.max_angular_speed,
                  control_hz=cfg.control_hz)
        return cls(action_mode=cfg.action_mode, **{**kw, **overrides})

    # -- state ------------------------------------------------------------------------------
    def _alloc(self, n: int) -> None:
        self.num_worlds = n
        self.phase = np.zeros(n, int)
        self.retries = np.zeros(n, int)
        self._counter = np.zeros(n, int)
        self._lost = np.zeros(n, int)
        self._plan_point = np.zeros((n, 3))
        self._plan_yaw = np.zeros(n)
        self._plan_width = np.zeros(n)
        self._plan_gap = np.full(n, JAW_GAP_MAX)
        self._plan_top = np.zeros(n)
        self._offset = np.zeros((n, 3))
        self._velocity = np.zeros((n, 3))
        self._last_gap = np.full(n, JAW_GAP_MAX)
        self._stall = np.zeros(n, int)
        self._fresh = np.ones(n, bool)
        self._contact_gap = np.full(n, JAW_GAP_MAX)
        self._force_hist = np.zeros((n, max(self.config.force_window, 1), 2))

    def reset(self, mask=None) -> None:
        """Restart the script of all worlds, or of the worlds where ``mask`` [N] is True."""
        if mask is None or self.num_worlds == 0:
            self._alloc(self.num_worlds)
            return
        m = np.asarray(mask, bool).reshape(-1)
        if m.shape != (self.num_worlds,):
            raise ValueError(f"mask must have shape ({self.num_worlds},), got {m.shape}")
        self.phase[m] = APPROACH
        self.retries[m] = 0
        self._counter[m] = 0
        self._lost[m] = 0
        self._velocity[m] = 0.0
        self._stall[m] = 0
        self._fresh[m] = True
        self._force_hist[m] = 0.0
        self._contact_gap[m] = JAW_GAP_MAX
        self._last_gap[m] = JAW_GAP_MAX

    # -- policy -----------------------------------------------------------------------------
    def __call__(self, obs) -> np.ndarray:
        if not isinstance(obs, dict) or "agent_pos" not in obs or "environment_state" not in obs:
            raise TypeError("obs must be a dict with 'agent_pos' and 'environment_state' "
                            "(the env's obs_type='state')")
        agent = np.asarray(obs["agent_pos"], np.float64)
        state = np.asarray(obs["environment_state"], np.float64)
        single = agent.ndim == 1
        agent, state = np.atleast_2d(agent), np.atleast_2d(state)
        if agent.shape[1:] != (AGENT_POS.size,) or state.shape[1:] != (ENV_STATE.size,) or len(agent) != len(state):
            raise ValueError(f"agent_pos must be [N, {AGENT_POS.size}] and environment_state [N, {ENV_STATE.size}], "
                             f"got {agent.shape} and {state.shape}")
        if not (np.all(np.isfinite(agent)) and np.all(np.isfinite(state))):
            raise ValueError("observation must be finite")
        if len(agent) != self.num_worlds:
            self._alloc(len(agent))
        action = self._act(agent, state)
        return action[0] if single else action

    def _hold_gap(self, gap: np.ndarray) -> np.ndarray:
        """Jaw gap command [n] (m) that holds a grip (CLOSE once the grip force is reached, and LIFT):
        ``grip_overtravel`` inside the gap of first touch, never wider than the current ``gap``."""
        return np.minimum(gap, self._contact_gap - self.config.grip_overtravel)

    def _act(self, agent: np.ndarray, state: np.ndarray) -> np.ndarray:
        c = self.config
        dt = c.dt
        n = self.num_worlds
        flange, quat = AGENT_POS.get(agent, "wrist_position"), AGENT_POS.get(agent, "wrist_quat")
        quat = quat / np.linalg.norm(quat, axis=1, keepdims=True)
        gap = np.clip(AGENT_POS.get(agent, "jaw_gap")[:, 0], JAW_GAP_MIN, JAW_GAP_MAX)
        f_left, f_right = AGENT_POS.get(agent, "tip_normal_force").T
        f_max = np.maximum(f_left, f_right)
        # the tip forces come with one- or two-step spikes of 10-1000 N while the FEM contact solve
        # is unconverged: decisions on "enough grip" use each pad's minimum over a short window
        self._force_hist = np.roll(self._force_hist, 1, axis=1)
        self._force_hist[:, 0, 0], self._force_hist[:, 0, 1] = f_left, f_right
        self._force_hist[self._fresh, 1:] = 0.0
        f_min = self._force_hist.min(axis=1).min(axis=1)
        feature, goal = ENV_STATE.get(state, "feature_position"), ENV_STATE.get(state, "goal")
        keypoints = ENV_STATE.get(state, "keypoints").reshape(n, NUM_KEYPOINTS, 3)
        x_axis = _quat_rotate(quat, np.tile([1.0, 0.0, 0.0], (n, 1)))
        yaw_now = np.arctan2(-x_axis[:, 2], x_axis[:, 0])
        tcp = flange + _quat_rotate(quat, tcp_offset(gap=gap))

        # gap progress (stall detection) and freshly reset worlds
        shrink = self._last_gap - gap
        self._last_gap = gap.copy()
        self._offset = np.where(self._fresh[:, None], feature - tcp, self._offset)
        self._fresh[:] = False

        # --- planning (APPROACH re-plans every step; later phases keep the frozen plan): only the
        # worlds that re-plan are planned (a world's plan depends on its own inputs only)
        replan = self.phase == APPROACH
        if replan.any():
            plan = plan_grasps(feature[replan], keypoints[replan], yaw_now[replan])
            self._plan_point[replan] = plan.point
            self._plan_yaw[replan] = plan.yaw
            self._plan_width[replan] = plan.width
            self._plan_gap[replan] = plan.open_gap
            self._plan_top[replan] = plan.top
        hover_y = self._plan_top + PAD_HALF_LENGTH + c.hover_clearance

        target_tcp = tcp.copy()
        target_yaw = self._plan_yaw.copy()
        gap_cmd = gap.copy()
        speed = np.full(n, c.max_linear_speed)
        phase = self.phase
        new_phase = phase.copy()

        # APPROACH: rise to hover height first if low, then over the grasp point, turn, preset gap
        ph = phase == APPROACH
        low = tcp[:, 1] < hover_y - 0.01
        far = np.linalg.norm((tcp - self._plan_point)[:, [0, 2]], axis=1) > 0.01
        target_tcp[ph, 1] = hover_y[ph]
        move_xz = ph & ~(low & far)
        target_tcp[move_xz, 0] = self._plan_point[move_xz, 0]
        target_tcp[move_xz, 2] = self._plan_point[move_xz, 2]
        gap_cmd[ph] = self._plan_gap[ph]
        yaw_err = np.abs(np.arctan2(np.sin(self._plan_yaw - yaw_now), np.cos(self._plan_yaw - yaw_now)))
        ready = (ph & (np.linalg.norm((tcp - target_tcp)[:, [0, 2]], axis=1) < c.position_tolerance)
                 & (np.abs(tcp[:, 1] - hover_y) < 0.01) & (yaw_err < c.yaw_tolerance)
                 & (np.abs(gap - self._plan_gap) < 0.002))
        new_phase[ready] = DESCEND

        # DESCEND: straight down to the grasp height; an unexpected touch starts the closing
        ph = phase == DESCEND
        target_tcp[ph] = self._plan_point[ph]
        speed[ph] = c.descend_speed
        gap_cmd[ph] = self._plan_gap[ph]
        arrived = ph & ((np.linalg.norm(tcp - self._plan_point, axis=1) < c.position_tolerance)
                        | (f_max > c.contact_force))
        self._plan_point[arrived & (f_max > c.contact_force), 1] = np.maximum(
            tcp[arrived & (f_max > c.contact_force), 1], PAD_HALF_LENGTH)
        new_phase[arrived] = CLOSE
        self._counter[arrived] = 0
        self._contact_gap[arrived] = JAW_GAP_MAX
        self._stall[arrived] = 0

        # CLOSE: fast to the estimate + margin, slow to contact, squeeze to grip_force
        ph = phase == CLOSE
        target_tcp[ph] = self._plan_point[ph]
        speed[ph] = c.descend_speed
        outside = gap > self._plan_width + c.approach_margin + 0.001  # float32 jaw commands: 1 mm slack
        touching = f_max > c.contact_force
        first = ph & touching & (self._contact_gap >= JAW_GAP_MAX)
        self._contact_gap[first] = gap[first]
        fast = ph & outside & ~touching
        gap_cmd[fast] = np.maximum(self._plan_width[fast] + c.approach_margin, JAW_GAP_MIN)
        lead = c.absolute_close_lead if self.action_mode == "absolute" else c.delta_close_lead
        slow = ph & ~outside & ~touching
        gap_cmd[slow] = gap[slow] - c.slow_close_speed * dt * lead
        squeeze = ph & touching & (f_min < c.grip_force)
        gap_cmd[squeeze] = gap[squeeze] - c.squeeze_speed * dt * lead
        held = ph & (f_min >= c.grip_force)
        gap_cmd[held] = self._hold_gap(gap)[held]
        self._counter = np.where(held, self._counter + 1, np.where(ph, 0, self._counter))
        stalled = ph & touching & (shrink < 1e-5)
        self._stall = np.where(stalled, self._stall + 1, np.where(ph, 0, self._stall))
        go_lift = ph & ((self._counter >= c.settle_steps) | (self._stall >= 3))
        new_phase[go_lift] = LIFT
        self._velocity[go_lift] = 0.0
        self._offset[go_lift] = (feature - tcp)[go_lift]
        missed = ph & (gap <= JAW_GAP_MIN + 0.001) & ~touching
        new_phase[missed] = RETREAT

        # LIFT: feature point to the goal; keep the grip
        ph = phase == LIFT
        a = c.offset_filter
        self._offset[ph] = (1 - a) * self._offset[ph] + a * (feature - tcp)[ph]
        target_tcp[ph] = goal[ph] - self._offset[ph]
        speed[ph] = c.lift_speed
        weak = (ph & (f_min < c.regrip_fraction * c.grip_force)
                & (gap > c.regrip_floor * self._contact_gap))
        hold_gap = self._hold_gap(gap)
        gap_cmd[ph] = hold_gap[ph]
        gap_cmd[weak] = np.minimum(hold_gap, gap - 0.5 * c.squeeze_speed * dt)[weak]
        self._lost = np.where(ph & (f_max < c.lost_force), self._lost + 1, np.where(ph, 0, self._lost))
        lost = ph & ((self._lost >= c.lost_steps) | (gap <= JAW_GAP_MIN + 0.0005))
        new_phase[lost] = RETREAT

        # RETREAT: open and rise, then plan again (if retries are left)
        ph = phase == RETREAT
        gap_cmd[ph] = JAW_GAP_MAX
        target_tcp[ph, 1] = np.maximum(hover_y[ph] + 0.02, tcp[ph, 1])
        clear = ph & (gap >= JAW_GAP_MAX - 0.002) & (tcp[:, 1] >= hover_y + 0.015)
        again = clear & (self.retries < c.max_retries)
        new_phase[again] = APPROACH
        self.retries[again] += 1

        # --- flange velocity from the tcp target (the tcp hangs lower as the fingers close)
        # gap one step ahead at the 2F-85 default (fastest) jaw speed, 150 mm/s
        next_gap = np.clip(gap + np.clip(gap_cmd - gap, -0.15 * dt, 0.15 * dt), JAW_GAP_MIN, JAW_GAP_MAX)
        flange_target = target_tcp - _quat_rotate(_yaw_quat(target_yaw), tcp_offset(gap=next_gap))
        lifting = phase == LIFT
        d = flange_target - flange
        dist = np.linalg.norm(d, axis=1)
        # braking profile while lifting (no overshoot with the acceleration limit), deadbeat otherwise
        speed = np.where(lifting, np.minimum(speed, np.sqrt(2.0 * 0.8 * c.lift_acceleration * dist)), speed)
        v = d / dt
        v *= np.minimum(1.0, speed / np.maximum(dist / dt, 1e-12))[:, None]
        dv = v - self._velocity
        dv_norm = np.linalg.norm(dv, axis=1)
        dv_max = c.lift_acceleration * dt
        dv *= np.where(lifting, np.minimum(1.0, dv_max / np.maximum(dv_norm, 1e-12)), 1.0)[:, None]
        v = self._velocity + dv
        self._velocity = v

        omega = _rotation_vector(_yaw_quat(target_yaw), quat) / dt
        linear, angular = v / c.max_linear_speed, omega / c.max_angular_speed
        linear /= np.maximum(np.abs(linear).max(axis=1, keepdims=True), 1.0)
        angular /= np.maximum(np.abs(angular).max(axis=1, keepdims=True), 1.0)
        self.phase = new_phase
        command = WristCommand(flange=flange, linear=linear, angular=angular, target_yaw=target_yaw, gap=gap_cmd)
        return ACTION_PACKERS[self.action_mode](command, c).astype(np.float32)
