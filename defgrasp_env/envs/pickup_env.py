"""``DeformablePickup-v0``: pick a soft FEM object off the ground and hold it at a goal."""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np

from .actions import DeviceActionDecoder, check_actions
from .common import SceneCamera, draw_world, observations, step_infos
from .config import PickupConfig
from .replay_spec import ReplaySpec
from .scene import PickupScene
from .task import PickupTask, action_space, observation_spaces

#: Reset-option prefixes of frameworks that drive the env (LeRobot's rollout passes
#: ``{"lerobot_new_rollout": True}``): such keys are ignored; any other unknown key is an error.
FOREIGN_OPTION_PREFIXES = ("lerobot_",)


def render_fps(control_hz: float) -> int | float:
    """``metadata["render_fps"]``: the control rate, an int where it is one (video writers such as
    PyAV's, used by lerobot-eval, need a rational frame rate)."""
    return int(control_hz) if float(control_hz).is_integer() else control_hz


def make_config(config: PickupConfig | None, kwargs: dict[str, Any]) -> PickupConfig:
    """A ``PickupConfig`` from keyword options (``object=``, ``youngs_modulus=``, ...)."""
    base = config if config is not None else PickupConfig()
    names = {f.name for f in dataclasses.fields(PickupConfig)}
    unknown = sorted(set(kwargs) - names)
    if unknown:
        raise TypeError(f"unknown option(s) {unknown}; accepted: {sorted(names)}")
    if isinstance(kwargs.get("youngs_modulus"), list):
        kwargs = {**kwargs, "youngs_modulus": tuple(kwargs["youngs_modulus"])}
    return dataclasses.replace(base, **kwargs)


def parse_reset_options(config: PickupConfig, options: dict | None) -> str | None:
    """The episode's object from the reset ``options`` (None: drawn), after checking them: keys
    other than ``object`` are refused (typos caught), except those of other frameworks, which start
    with one of ``FOREIGN_OPTION_PREFIXES`` and are ignored."""
    unknown = sorted((k for k in options or {} if k != "object"
                      and not (isinstance(k, str) and k.startswith(FOREIGN_OPTION_PREFIXES))), key=repr)
    if unknown:
        raise ValueError(f"reset options must be a subset of ['object'], got {unknown} (keys starting "
                         f"with {list(FOREIGN_OPTION_PREFIXES)} are ignored)")
    name = (options or {}).get("object")
    if name is not None and name not in config.object_names:
        raise ValueError(f"reset option object must be one of {list(config.object_names)}, got {name!r}")
    return name


class DeformablePickupEnv(gym.Env):
    """Pick up a deformable object with a Robotiq 2F-85-like gripper and lift it to a goal.

    The object is a tetrahedral FEM body (fixed-corotated hyperelasticity, Warp) resting on the
    ground (y = 0, world y up) at the paper's initial pose [0, 0, 0] (plus seeded noise); the goal
    is ``goal`` ([0, 0.6, 0] m), or drawn per episode within ``goal`` +- ``goal_noise`` (m, per
    axis; e.g. goals from near the ground up, a curriculum for RL). The gripper hangs on an
    invisible 6-DOF wrist (3 prismatic + 3 revolute joints, ``defgrasp_env/assets/wrist_6dof.urdf``);
    its pads are kinematic boxes with Coulomb friction. One step is one control period (default
    1/20 s). The wrist is force-limited like a collaborative arm: within each physics substep, wrist
    and closing jaw move only the fraction of their motion that keeps the net force of the pads on
    the object (``wrist_force``) within ``wrist_force_limit`` (default 150 N, a UR e-Series default
    safety limit) and each pad's normal
    force within ``gripper.grip_force_limit`` + ``wrist_force_limit``, both +10 %
    (``wrist.force_limit``; forces of a converged solve; wrist and jaw stop, and a stopped wrist
    the object still pushes over the limit backs off along that push; a stopped pad still takes the
    impact of an object it threw within the substep, and a pad embedded in an object reads its
    clamp: README, known gaps); between substeps the jaw holds the grip force at
    ``gripper.grip_force_limit``. No node goes through a pad at any legal speed; a state
    with a node deeper than 1 mm in a pad or the ground is flagged (``sim_penetrated``).

    **Action space** (``action_mode``; names, slices, units and bounds in ``defgrasp_env.layout``):
      * ``"delta"`` (default, ``DELTA_ACTION``): Box [-1, 1]^7 = flange linear velocity (3) x
        ``max_linear_speed`` (m/s, world frame), flange angular velocity (3, axis-angle rate) x
        ``max_angular_speed`` (rad/s, world frame), jaw command (1): -1 fully open (85 mm, the
        2F-85 stroke) ... +1 fully closed (1.5 mm); the jaw moves toward it at the gripper's closing
        speed and holds the grip force at its force limit.
      * ``"absolute"`` (``ABSOLUTE_ACTION``): Box [8] = target flange position (3, m), orientation
        quaternion xyzw (4), jaw gap (1, m, [0, 0.085]); reached at most at the speed limits (used
        by teleoperation).
      * ``"topdown"`` (``TOPDOWN_ACTION``): Box [5] = flange linear velocity (3, as ``"delta"``),
        target yaw (1, rad, [-pi, pi]: the flange pointing down, turned about world +y; turned to at
        most at ``max_angular_speed``, roll and pitch back to pointing down), jaw command (1, as
        ``"delta"``): top-down grasping with the wrist's turn as a target (for imitation: a learner
        regresses a held target yaw, where the delta expert's saturated turn rate flips sign with the
        object's orientation).
      Out-of-range values are clipped to the box; NaN/inf or a wrong shape raise ``ValueError``.

    **Observation space** (Dict, float32 unless noted; LeRobot's sim-env keys; ``AGENT_POS`` and
    ``ENV_STATE`` of ``defgrasp_env.layout``):
      * ``agent_pos`` [10]: flange position (3, m, world), flange quaternion xyzw (4), jaw gap
        (1, m, [0.0015, 0.085]), left and right tip normal force (2, N, >= 0).
      * ``environment_state`` [33] (``obs_type="state"``): object feature point = mean node position
        (3, m), its velocity (3, m/s), goal (3, m), 8 fixed surface keypoints (24, m, world).
      * ``pixels`` [H, W, 3] uint8 (``obs_type`` "pixels" or "pixels_agent_pos"): camera image.

    **Reward**: ``reach + grasp + lift + place + success + force`` (each also in ``info["reward_<term>"]``):
    reach = 0.5 (1 - tanh(5 |tcp - feature|)); grasp = 0.5 q when both tip forces exceed 0.5 N
    (grasped); lift = 2 q (1 - tanh(2 |feature - goal|)) while grasped (rising over the whole 0.58 m
    lift); place = q (1 - tanh(10 |feature - goal|)) while grasped (a sharp maximum at the goal, where
    the object must stay for the success hold); success = 10 on the success step; force =
    -min(max(wrist_force - 50 N, 0) / 100 N, 1), a cost of pressing the object with the pads (into the
    ground, or striking it): free up to 50 N (the scripted expert's episodes stay below 30 N), -1 from
    150 N, the default wrist force limit, on (fixed in N whatever ``wrist_force_limit``). Distances
    in m; ``envs.task.REACH_SCALE``, ``LIFT_SCALE``, ``PLACE_SCALE``, ``FORCE_FREE``, ``FORCE_SCALE``.
    q in [0, 1] is the grasp quality (``info["grasp_quality"]``, 0 while not grasped;
    ``envs.task.grasp_quality``): the worse pad's margin inside the pads' friction cone times a
    centring factor, 1 - tanh(70 x how far the feature point lies beyond the pad faces across their
    width); ~1 for an antipodal, centred hold (the
    scripted expert's read 0.9-1.0 on all five objects), ~0.1 for a cube pinched at its edge beside
    the pads.

    **Episode end**: terminated on success = feature point within ``success_tolerance`` (0.05 m) of
    the goal, grasped and not pierced (no node 5 mm deep in a pad or the ground, no pad edge 5 mm
    beyond the 0.5 mm skin inside the object, no tet centroid 5 mm deep in a pad), for
    ``success_hold_seconds`` (0.5 s) (with ``terminate_on_success=False`` the episode goes on, and
    the success and its term of 10 repeat on every further step held there: for training);
    truncated after ``episode_seconds`` (15 s, via ``max_episode_steps``) or when the simulation
    diverges (``info["sim_diverged"]``: the state is then kept at its last finite value).

    **Info**: ``is_success``, ``grasped``, ``grasp_quality``, ``pierced``, ``goal_distance`` (m),
    reward terms, tip forces (N), ``wrist_force`` (N, net force of the pads on the object), jaw gap (m), mean von
    Mises stress (Pa), solver iterations (of the accepted solves, summed over substeps; a force-limit
    retry is not counted)/residual/penetration (m), ``pad_embedding`` (m: how deep the object's
    material lies inside a pad, its deepest tet centroid; node contact keeps nodes out of the pads,
    not the material between them), ``sim_diverged``,
    ``sim_converged`` (Newton met its tolerance in every substep), ``sim_penetrated`` (a node ended
    deeper than ``solver.penetration_bound``, 1 mm, in a pad or the ground, or a pad's edge that
    much beyond the 0.5 mm skin inside the object, measured to its surface: ``penetration`` is the
    deepest of these over the step's substeps); ``reset`` returns
    ``is_success``, ``object``, ``youngs_modulus`` (Pa), ``goal`` (m, [3]) and ``replay_spec`` (a
    ``ReplaySpec``: seed or RNG state, options, object, material, initial pose, goal and the reset
    that built the simulation;
    ``spec.reset(env)`` repeats the reset bit for bit).

    **Arguments**: every field of ``PickupConfig`` as a keyword (``object``: a name, ``"random"``,
    a mesh path, or a tuple of names and paths drawn from per episode; ``youngs_modulus``
    (value or tuple to sample), ``poisson_ratio``, ``density``, ``ground_friction``,
    ``pad_friction``, ``init_position_noise``, ``init_yaw_noise``, ``control_hz``,
    ``max_linear_speed`` (m/s, <= 2), ``max_angular_speed`` (rad/s), ``wrist_force_limit`` (N),
    ``camera``, ``gripper``, ``solver``, ``obs_type``, ``action_mode``, ``device``), plus
    ``render_mode``: ``"rgb_array"`` (``render()`` returns the camera image) or ``"human"`` (a 3D
    view in the browser, ``defgrasp_env.viewer``, needs the ``[viewer]`` extra: ``reset`` and every
    ``step`` draw the scene; the URL is printed; no display needed; ``viewer_host`` (default
    127.0.0.1) and ``viewer_port`` (default 8080, 0: any free port) set where it is served: forward
    it over SSH with ``ssh -L 8080:127.0.0.1:8080 HOST``).

    **Reset options**: ``{"object": name}`` picks the episode's object among the configured ones
    (for ``object="random"``; the random draw is still made, so the other draws stay the same).
    Keys starting with a framework prefix in ``FOREIGN_OPTION_PREFIXES`` (``"lerobot_"``) are
    ignored, so LeRobot's rollout markers pass; any other key is rejected with a ``ValueError``, so a
    typo such as ``{"objet": ...}`` never silently does nothing.

    **Full state** beyond observations: ``env.unwrapped.scene`` (node positions, forces, stresses).

    **Version history**: v0: first release.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 20}

    def __init__(self, render_mode: str | None = None, config: PickupConfig | None = None,
                 viewer_host: str = "127.0.0.1", viewer_port: int = 8080, **kwargs):
        self.config = make_config(config, kwargs)
        if render_mode not in (None, "rgb_array", "human"):
            raise ValueError(f"render_mode must be None, 'rgb_array' or 'human', got {render_mode!r}")
        self.render_mode = render_mode
        self._viewer = None
        if render_mode == "human":
            from ..viewer import LiveSceneViewer, check_port_free

            check_port_free(viewer_host, viewer_port, "viewer_port")
            self._viewer = LiveSceneViewer(host=viewer_host, port=viewer_port)
        self.metadata = {**self.metadata, "render_fps": render_fps(self.config.control_hz)}
        self.observation_space = observation_spaces(self.config)
        self.action_space = action_space(self.config)
        self.scene: PickupScene | None = None
        self._scene_origin: ReplaySpec | None = None  # the reset that built ``scene``
        #: the task's observations, reward and flags on the simulation's device (made at the first reset)
        self.task: PickupTask | None = None
        self._decoder: DeviceActionDecoder | None = None  # the actions' decoding on the device (the same)
        self._camera = SceneCamera(self.config)

    # -- gym API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        name = parse_reset_options(self.config, options)
        setup, spec = draw_world(self.config, self.np_random, seed, name, options)
        if self.scene is None or self.scene.object_names[0] != setup.object_name:
            self.scene = PickupScene(self.config, [setup])
            self._scene_origin = spec
        else:
            self.scene.reset_worlds(np.ones(1, bool), [setup])
            spec = dataclasses.replace(spec, scene_origin=self._scene_origin)
        if self.task is None:
            self.task = PickupTask(self.config, 1)
            self._decoder = DeviceActionDecoder(self.config, 1)
        self.task.reset(np.ones(1, bool), setup.goal[None])
        self.task.observe(self.scene)
        if self._viewer is not None:
            self._viewer.new_episode()
            self.render()
        return self._obs(), {"is_success": False, "object": setup.object_name,
                             "youngs_modulus": setup.material.youngs_modulus, "goal": setup.goal.copy(),
                             "replay_spec": spec}

    def step(self, action):
        if self.scene is None:
            raise RuntimeError("call reset() before step()")
        a = check_actions(action, self.action_space.shape, self.action_space.low, self.action_space.high)[None]
        self._decoder.decode(self.scene.gripper, a)  # the targets, on the device
        stats = self.scene.step_to_gripper_targets()
        self.task.evaluate(self.scene)  # on the device; observations too
        result = self.task.result()
        info = {k: v[0].item() for k, v in step_infos(result, stats).items()}
        terminated = bool(result["terminated"][0])
        truncated = bool(result["truncated"][0])  # the simulation diverged (the time limit: ``TimeLimit``)
        if self._viewer is not None:
            self.render()
        return self._obs(), float(result["reward"][0]), terminated, truncated, info

    def render(self):
        if self.render_mode == "human" and self.scene is not None:
            self._viewer.show(self.scene, 0, self.task.goal(0), time_s=float(self.task.elapsed[0]) * self.config.dt)
        if self.render_mode != "rgb_array":
            return None
        return self._render_world(0)

    def close(self):
        if self._viewer is not None:
            self._viewer.close()
        self._camera = SceneCamera(self.config)
        self.scene = None

    # -- internals -------------------------------------------------------------------------
    def _obs(self):
        pixels = self._render_world(0)[None] if "pixels" in self.observation_space.spaces else None
        return {k: v[0] for k, v in observations(self.task, pixels).items()}

    def _render_world(self, w: int) -> np.ndarray:
        return self._camera.render(self.scene, w, self.task.goal(w))
