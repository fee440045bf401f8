"""Observations, reward terms, success and episode bookkeeping of the pickup task, batched over W."""

from __future__ import annotations

import numpy as np
import warp as wp
from gymnasium import spaces

from ..gripper import PAD_BOX_HALF_EXTENTS
from ..layout import ACTION_LAYOUTS, AGENT_POS, ENV_STATE, VectorLayout
from ..transforms import quat_to_matrix
from ..sim.launch_cache import LaunchCache
from .config import PickupConfig
from .scene import PickupScene
from .task_kernels import (OBSERVATION_SIZE, OUTPUT_COLUMNS, RESULT_COLUMNS, TaskParams, column, evaluate_worlds,
                           observe_worlds, reset_counters)

REWARD_TERMS = ("reach", "grasp", "lift", "place", "success", "force")
#: Both tip normal forces above this (N) count as a grasp.
GRASP_FORCE = 0.5
#: Deepest penetration (m) beyond which the object counts as pierced: of a node in a pad or the
#: ground, of a pad's edge inside the object beyond the 0.5 mm skin (``SolveStats.penetration``),
#: or of the object's material in a pad (``PickupScene.pad_embedding``: a pad sunk in between
#: surface nodes or pushed into the object).
PIERCE_DEPTH = 0.005
#: Distance scales (1/m) of the shaped reach and lift terms, ``1 - tanh(scale * distance)``: each
#: term must still rise over the whole distance a learner covers, the reach from the start pose
#: (~0.1-0.2 m) and the lift from the ground to the goal (0.58 m). With the earlier 10/m and 5/m the
#: lift term was flat below 0.3 m (0.01 on the ground, rising ~0.2 per m over the first 10 cm).
REACH_SCALE = 5.0
LIFT_SCALE = 2.0
#: Distance scale (1/m) of the place term ``1 - tanh(scale * |feature - goal|)``: a sharp maximum at
#: the goal on top of the broad lift term. With the lift term alone (4 per m at the goal) a PPO policy
#: learned to lift the cuboid through the goal at full speed to the wrist's upper limit and never
#: held it there for ``success_hold_seconds`` (2.9 M steps, benchmarks/RESULTS.md); ManiSkill's pick
#: tasks shape their place reward with 5/m over a goal 0.1-0.3 m away.
PLACE_SCALE = 10.0
#: The force term ``-min(max(wrist_force - FORCE_FREE, 0) / FORCE_SCALE, 1)`` (N): pressing the object
#: with the pads' net force (into the ground, or striking it) costs up to 1 a step, the full cost at
#: 150 N (the default wrist force limit). Free up to 50 N: the scripted expert's episodes (five objects
#: at E = 1e4, 1e6, 1e7, two seeds each) read at most 29 N. Without it a PPO policy learned to strike
#: the cube at the wrist's force limit before grasping it (sim_penetrated steps in half its episodes),
#: and such worlds need the most Newton iterations of a batch (the force limit's patient re-solves:
#: 50-110 a step, against a median of 5-16; benchmarks/RESULTS.md, 2026-11-28). Fixed in N: a
#: ``wrist_force_limit`` other than the default moves the limit, not the cost.
FORCE_FREE = 50.0
FORCE_SCALE = 100.0


#: Distance scale (1/m) of the grasp quality's centring factor ``1 - tanh(scale * beyond)`` (beyond:
#: how far the object's feature point lies outside the pad faces across their width): 0.86 at 2 mm,
#: 0.60 at 6 mm, 0.12 at 20 mm. The scripted expert's holds of all five objects read 0 mm; PPO's
#: failed cuboid holds (pads pinching the cube's edge beside it, pressing down at the wrist's force
#: limit) 16-22 mm, its successes 6-8 mm (benchmarks/RESULTS.md, 2026-11-26).
CENTRE_SCALE = 70.0


def grasp_quality(pad_force_angles: np.ndarray, pad_friction: float, beyond_pad_faces: np.ndarray) -> np.ndarray:
    """[W] in [0, 1]: how sound a hold is, the product of two factors, 1 for the scripted expert's
    antipodal, centred holds:

    * the friction-cone margin of the worse pad, ``(cos(angle) - cos(cone)) / (1 - cos(cone))``
      clipped to [0, 1], cone = atan(``pad_friction``): 1 where both pads are pushed straight out
      along the closing axis, 0 where a pad's force lies on the cone (held by friction alone: it
      slips on any further load, as a wedge squeezed out between the pads does);
      ``pad_force_angles`` [W, 2] rad (``Gripper.pad_force_angles``). ManiSkill's ``is_grasping``
      gates its grasps on the same angle (at a fixed 85 degrees);
    * the centring ``1 - tanh(CENTRE_SCALE * beyond_pad_faces[:, 1])``: ``beyond_pad_faces`` [W, 2]
      m (``feature_beyond_pad_faces``: along the pads' length, across their width), 1 where the
      object's feature point lies within the pad faces' width: an object held beside its centre
      (pinched at an edge) reads less. Along the pads' length it is not counted: a soft object held
      near its top, or a torus held by its rim, hangs below the pads (the expert's soft torus: 10 mm).
    """
    cone = np.cos(np.arctan(pad_friction))
    worst = np.cos(np.max(pad_force_angles, axis=1))
    if cone >= 1.0:  # frictionless pads: only a force straight along the closing axis holds
        margin = (worst >= 1.0).astype(np.float64)
    else:
        margin = np.clip((worst - cone) / (1.0 - cone), 0.0, 1.0)
    return margin * shaped_progress(beyond_pad_faces[:, 1], CENTRE_SCALE)


def feature_beyond_pad_faces(feature: np.ndarray, pad_positions: np.ndarray, pad_quats: np.ndarray) -> np.ndarray:
    """[W, 2] m: how far each world's feature point ``feature`` [W, 3] (m, world) lies beyond the
    rectangle of the pad faces, along the pads' length (finger direction) and width, the larger of
    the pads; 0 where it lies between the faces. Pad box centres ``pad_positions`` [W, P, 3] m and
    orientations ``pad_quats`` [W, P, 4] xyzw (world; ``Gripper.pad_poses``). A hold whose feature
    point lies beyond the faces holds the object off its centre: a prism gripped across its width
    near its top (a sound grasp), or, with a jaw gap below the object's width there, on the pads'
    edges or corners (a sphere pinched above its equator, a cube across an edge). The scripted
    expert's holds read 0 across the width for all five objects (the torus's rim lies along the
    closing axis, which is not counted; a soft torus hangs ~10 mm below the pads' length)."""
    half = np.asarray(PAD_BOX_HALF_EXTENTS, np.float64)[1:]  # length, width (x: the closing axis)
    # the feature point in each pad's frame: R^T (feature - pad centre), [W, P, 3]
    rot = quat_to_matrix(np.asarray(pad_quats, np.float64))
    offset = np.asarray(feature, np.float64)[:, None, :] - np.asarray(pad_positions, np.float64)
    local = np.einsum("wpji,wpj->wpi", rot, offset)
    return np.maximum(np.abs(local[..., 1:]) - half, 0.0).max(axis=1)


def shaped_progress(distance: np.ndarray, scale: float) -> np.ndarray:
    """Dense progress in (0, 1]: ``1 - tanh(scale * distance)`` (distance m, scale 1/m), 1 at 0."""
    return 1.0 - np.tanh(scale * np.asarray(distance, np.float64))


def _box(layout: VectorLayout) -> spaces.Box:
    """float32 Box of a layout's bounds."""
    low, high = layout.bounds()
    return spaces.Box(low.astype(np.float32), high.astype(np.float32), (layout.size,), np.float32)


def observation_spaces(config: PickupConfig) -> spaces.Dict:
    """Observation space of one world (bounds from ``defgrasp_env.layout``)."""
    entries = {}
    if config.obs_type in ("state", "pixels_agent_pos"):
        entries["agent_pos"] = _box(AGENT_POS)
    if config.obs_type == "state":
        entries["environment_state"] = _box(ENV_STATE)
    if config.obs_type in ("pixels", "pixels_agent_pos"):
        cam = config.camera
        entries["pixels"] = spaces.Box(0, 255, (cam.height, cam.width, 3), np.uint8)
    return spaces.Dict(entries)


def action_space(config: PickupConfig) -> spaces.Box:
    """Action space of one world: ``DELTA_ACTION`` [-1, 1]^7, ``ABSOLUTE_ACTION`` (pos(3) m, quat
    xyzw(4), gap(1) m) or ``TOPDOWN_ACTION`` (velocity(3) in [-1, 1], yaw(1) rad, jaw(1) in [-1, 1]),
    see ``defgrasp_env.layout``."""
    return _box(ACTION_LAYOUTS[config.action_mode])


def _step_limit(max_episode_steps: int | None) -> int:
    """``max_episode_steps`` as the kernels' int32 (None or beyond int32: never)."""
    limit = np.iinfo(np.int32).max
    if max_episode_steps is None:
        return limit
    if int(max_episode_steps) < 1:
        raise ValueError(f"max_episode_steps must be >= 1, got {max_episode_steps!r}")
    return min(int(max_episode_steps), limit)


class PickupTask:
    """Observations, reward, success and termination of the worlds of a ``PickupScene``, computed
    on the simulation's device (``task_kernels``: one thread per world) from the gripper's state, the
    scene's readouts and the solver's report, into ``outputs``: one float64 row per world
    (``task_kernels.OUTPUT_COLUMNS``: the observation vectors, then the step's result), brought to
    the host in one download (:meth:`download`) or read on the device as torch tensors
    (:meth:`torch_outputs`).

    Args:
        config: the env's config (goal, success tolerance and hold, pad friction, device).
        num_worlds: W.
        max_episode_steps: steps after which a world's episode is truncated (``None``: never; the
            single env leaves that to Gymnasium's ``TimeLimit``).
    """

    def __init__(self, config: PickupConfig, num_worlds: int, max_episode_steps: int | None = None):
        self.config = config
        self.num_worlds = num_worlds
        self.hold_steps = int(round(config.success_hold_seconds * config.control_hz))
        self.device = d = wp.get_device(config.device)
        p = TaskParams()
        p.success_tolerance = float(config.success_tolerance)
        p.friction_cone = float(np.cos(np.arctan(config.pad_friction)))
        p.hold_steps = self.hold_steps
        p.max_episode_steps = _step_limit(max_episode_steps)
        p.terminate_on_success = int(config.terminate_on_success)
        p.grasp_force = GRASP_FORCE
        p.pierce_depth = PIERCE_DEPTH
        p.reach_scale, p.lift_scale, p.place_scale, p.centre_scale = REACH_SCALE, LIFT_SCALE, PLACE_SCALE, CENTRE_SCALE
        p.force_free, p.force_scale = FORCE_FREE, FORCE_SCALE
        self.params = p
        self._goals_host = np.tile(np.asarray(config.goal, dtype=np.float64), (num_worlds, 1))
        self._goals = wp.array(self._goals_host, dtype=wp.vec3d, device=d)  # each world's goal, m, world
        self._held = wp.zeros(num_worlds, dtype=wp.int32, device=d)
        self._elapsed = wp.zeros(num_worlds, dtype=wp.int32, device=d)
        #: [W, len(OUTPUT_COLUMNS)] float64 on the device: the last observation and step result
        self.outputs = wp.zeros((num_worlds, len(OUTPUT_COLUMNS)), dtype=wp.float64, device=d)
        self._live = wp.ones(num_worlds, dtype=wp.int32, device=d)  # evaluate's ``live`` on the device
        self._live_host = np.ones(num_worlds, np.int32)
        self._host: np.ndarray | None = None  # ``outputs`` downloaded since its last change
        self._launches = LaunchCache(d)
        self._bound: tuple = ()  # the scene arrays the recorded launches are bound to (ids)

    def _records_for(self, *arrays) -> LaunchCache:
        """The launch records for kernels reading ``arrays`` (arrays the records hold, so their ids
        stay unique while bound): dropped when the scene's arrays were replaced (a rebuilt scene),
        so that no record keeps an old scene's arrays alive."""
        ids = tuple(id(a) for a in arrays)
        if ids != self._bound:
            self._launches = LaunchCache(self.device)
            self._bound = ids
        return self._launches

    @property
    def elapsed(self) -> np.ndarray:
        """[W] int: control steps taken in each world's episode (downloaded)."""
        return self._elapsed.numpy().astype(np.int64)

    @property
    def goals(self) -> np.ndarray:
        """[W, 3] float64: each world's goal of its episode (m, world; a copy)."""
        return self._goals_host.copy()

    def goal(self, w: int) -> np.ndarray:
        """[3] float64: world ``w``'s goal (m, world; a copy)."""
        return self._goals_host[w].copy()

    def reset(self, mask: np.ndarray, goals: np.ndarray | None = None) -> None:
        """Worlds in ``mask`` [W] bool start a new episode (no step taken, not at the goal), with
        the goals ``goals[mask]`` ([W, 3] m, world; None: the config's goal)."""
        mask = np.asarray(mask, dtype=bool)
        new = np.asarray(self.config.goal, dtype=np.float64) if goals is None else np.asarray(goals, dtype=np.float64)
        new = np.broadcast_to(new, (self.num_worlds, 3))[mask]
        if not np.array_equal(new, self._goals_host[mask]):  # uploaded only when a goal changes
            self._goals_host[mask] = new
            self._goals.assign(self._goals_host)
        mask = wp.array(np.asarray(mask, dtype=np.int32), dtype=wp.int32, device=self.device)
        wp.launch(reset_counters, dim=self.num_worlds, inputs=[mask, self._held, self._elapsed], device=self.device)

    def observe(self, scene: PickupScene) -> None:
        """Write the observation columns of ``outputs`` for the scene's current state."""
        self._observe(scene, scene.device_readouts())

    def _observe(self, scene: PickupScene, r) -> None:
        g, st, report = scene.gripper.arrays, scene.state, scene.solve_report.records
        self._records_for(r.feature_position, g.q, st.mean_von_mises, report).launch(
            "observe", observe_worlds, self.num_worlds,
            [g.q, g.gap, g.tip_force, r.feature_position, r.feature_velocity, r.keypoints, self._goals, self.params],
            [self.outputs])
        self._host = None

    def evaluate(self, scene: PickupScene, live: np.ndarray | None = None,
                 max_episode_steps: int | None = None) -> None:
        """After a control step: write every column of ``outputs`` (observations and the step's
        result: reward terms, success, divergence, termination, truncation, info readings) and
        advance the worlds' step and goal-hold counters. ``live`` [W] bool (default all): worlds
        whose step counts; the others (being reset) get no reward and no flags.
        ``max_episode_steps``: the truncation limit from now on (default: unchanged)."""
        r, g, st, report = scene.device_readouts(), scene.gripper.arrays, scene.state, scene.solve_report.records
        live = np.ones(self.num_worlds, np.int32) if live is None else np.asarray(live, dtype=bool).astype(np.int32)
        if not np.array_equal(live, self._live_host):  # uploaded only when it changes
            self._live.assign(live)
            self._live_host = live
        records = self._records_for(r.feature_position, g.q, st.mean_von_mises, report)
        limit = self.params.max_episode_steps if max_episode_steps is None else _step_limit(max_episode_steps)
        if limit != self.params.max_episode_steps:
            self.params.max_episode_steps = limit
            records = self._launches = LaunchCache(self.device)  # the records bake the parameters in
        records.launch("evaluate", evaluate_worlds, self.num_worlds,
                       [g.q, g.gap, g.tip_force, g.pad_force, r.feature_position, r.finite, r.pad_embedding,
                        report, st.mean_von_mises, self._live, self._goals, self.params, self._held, self._elapsed],
                       [self.outputs])
        self._observe(scene, r)

    def download(self) -> np.ndarray:
        """``outputs`` on the host [W, len(OUTPUT_COLUMNS)] (read-only; one transfer per change)."""
        if self._host is None:
            values = self.outputs.numpy()
            self._host = values.copy() if self.device.is_cpu else values
            self._host.flags.writeable = False
        return self._host

    def result(self) -> dict[str, np.ndarray]:
        """The step result columns as [W] arrays: ``reward`` and the ``reward_<term>`` (float64),
        the flags (``is_success``, ``grasped``, ``pierced``, ``sim_diverged``, ``terminated``,
        ``truncated``: bool), ``elapsed`` (int64) and the readings (float64)."""
        out = self.download()
        flags = ("is_success", "grasped", "pierced", "sim_diverged", "terminated", "truncated")
        values = {name: out[:, column(name)] for name in RESULT_COLUMNS}
        for name in flags:
            values[name] = values[name] != 0.0
        values["elapsed"] = values["elapsed"].astype(np.int64)
        return {name: np.array(v) for name, v in values.items()}

    def observations(self) -> dict[str, np.ndarray]:
        """The observation dict [W, ...] float32 of ``config.obs_type`` (without pixels)."""
        out = self.download()
        return {name: out[:, sl].astype(np.float32) for name, sl in self._observation_columns()}

    def torch_outputs(self, names: tuple[str, ...] = ()) -> dict:
        """Torch tensors on the simulation's device, made there from ``outputs`` (no host round
        trip): the observation dict (float32 [W, ...]) and the result columns ``names`` ([W]:
        ``reward`` float32 as the observations, flags bool)."""
        import torch

        wp.synchronize_device(self.device)  # ``outputs`` written (Warp's stream) before torch reads it
        # (two whole-device synchronisations: ~10 us each, against a step's milliseconds)
        t = wp.to_torch(self.outputs)
        values = {name: t[:, sl].to(torch.float32) for name, sl in self._observation_columns()}
        for name in names:
            col = t[:, column(name)]
            values[name] = col.to(torch.float32) if name.startswith("reward") else col != 0.0
        wp.synchronize_device(self.device)  # the copies made (torch's stream) before a step overwrites it
        return values

    def _observation_columns(self):
        spaces_ = []
        if self.config.obs_type in ("state", "pixels_agent_pos"):
            spaces_.append(("agent_pos", slice(0, AGENT_POS.size)))
        if self.config.obs_type == "state":
            spaces_.append(("environment_state", slice(AGENT_POS.size, OBSERVATION_SIZE)))
        return spaces_
