"""Native vector env of DeformablePickup-v0: N worlds in ONE FEM simulation (not N envs)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import dataclasses

import numpy as np
import warp as wp
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .actions import DeviceActionDecoder, check_actions
from .common import SceneCamera, draw_world, observations, step_infos
from .config import PickupConfig
from .pickup_env import make_config, render_fps
from .scene import PickupScene
from .seeds import world_seeds
from .task import PickupTask, action_space, observation_spaces


#: The step result columns ``torch_outputs`` returns as tensors (with the observations).
_STEP_RESULT = ("reward", "terminated", "truncated")


def check_world_objects(world_objects: Sequence[str] | None, num_envs: int,
                        allowed: tuple[str, ...]) -> tuple[str, ...] | None:
    """``world_objects`` as a tuple after checking it: None, or ``num_envs`` names each in
    ``allowed`` (the config's objects). TypeError for a str (not a sequence of names), ValueError
    for another length or for an entry not in ``allowed`` (naming it and its index)."""
    if world_objects is None:
        return None
    if isinstance(world_objects, str):
        raise TypeError(f"world_objects must be a sequence of {num_envs} object names, got the str {world_objects!r}")
    names = tuple(world_objects)
    if len(names) != num_envs:
        raise ValueError(f"world_objects must name one object per world ({num_envs}), got {len(names)}")
    for i, name in enumerate(names):
        if name not in allowed:
            raise ValueError(f"world_objects[{i}] must be one of the config's objects {list(allowed)} "
                             f"(set object= to 'random' or a tuple holding it), got {name!r}")
    return names


class DeformablePickupVectorEnv(VectorEnv):
    """``gym.make_vec("DeformablePickup-v0", num_envs=N, ...)``: N worlds stepped together.

    Spaces, reward and observations are those of ``DeformablePickupEnv`` (batched on a leading axis
    of N); the reset option is ``reset_mask`` (below). World ``i`` reset with seed ``s + i`` draws exactly what a single env reset
    with seed ``s + i`` draws, so the vector env equals N single envs on those seeds.
    Every episode of every world draws its object (``object="random"``: one of the five shapes; a
    tuple of names and mesh paths: one of those), Young's modulus, pose noise and the rest, from
    that world's RNG, as a single env reset on the same seed or RNG state draws them; ``reset`` and
    every autoresetting ``step`` report them per reset world in ``info["object"]`` (object array
    [N] of str), ``info["youngs_modulus"]`` ([N] Pa), with masks ``_object`` / ``_youngs_modulus``.

    ``world_objects`` (a sequence of N names, each one of the config's objects) instead fixes world
    ``i``'s object to ``world_objects[i]`` for every episode (the rest is drawn as before: E, pose,
    ...), as a single env reset with ``options={"object": world_objects[i]}`` draws it (its
    ``ReplaySpec`` carries that option). Worlds with different objects then keep their rows for
    good: packed (the solver's work is exactly the sum of the objects, the fastest layout when
    the objects need not change). Example (each of the five objects in a fifth of the worlds;
    ``OBJECT_SHAPES`` from ``defgrasp_env.sim``): ``gym.make_vec(..., num_envs=N,
    object="random", world_objects=[list(OBJECT_SHAPES)[i % 5] for i in range(N)])``.

    Storage of worlds with different objects (node and tet counts differ by world), chosen by the
    scene (``PickupScene.slots``; ``model.world_nodes(w)`` / ``world_tets(w)`` are a world's object
    rows either way):
    - Slotted (the default on a CUDA device when the config names several objects and
      ``world_objects`` is not given): every world gets the rows of the largest of the config's
      objects (``world_models.slot_sizes``), its object the first, the rest spare (parked 1 km up,
      fixed, massless; spare tets are skipped by the tet kernels and add exact zeros). A reset that
      changes a world's object rewrites that world's rows in place (``world_models.rewrite_worlds``,
      one scatter per array for all reset worlds): no array is reallocated, so the solver's
      recorded launches and captured graphs stay, and other worlds are not touched. Results are
      the packed layout's, bit for bit on the CPU (``tests/test_world_slots.py``). Cost: the spare
      rows' node work (on an H200, ``object="random"`` without resets 6-15 % below packed); a
      learner's batch whose episodes end at different steps resets some world to another object
      at nearly every step, which slots make 1.9-2.7x faster than rebuilding (benchmarks/RESULTS.md).
    - Packed (the CPU default, a single object, or ``world_objects``): nodes and tets packed in flat
      arrays with per-world offsets (``model.node_start``, ``model.tet_start``). A reset that changes
      the object of any world rebuilds the model, solver and state for the new objects
      (``PickupScene.reset_worlds``) and copies every other world's full state to its new offsets
      with one gather kernel per state array on the simulation's device; the grippers' per-world
      state has no offsets and is kept. Untouched worlds stay bit-identical, and step on bit for
      bit as before (the solver keeps no state across steps). Cost: the assembly of all worlds'
      model from cached one-world models (``world_models.assemble_model``: concatenation, equal
      to ``build_model`` bit for bit), new solver scratch and state arrays, and the solver's launch
      recording and graph captures at the next step (on a CPU with tens of worlds cheaper than
      stepping spare rows).
    A world's material drawn at a reset is written in place for all reset worlds at once
    (``sim.model.set_world_materials``).

    Autoreset (``autoreset_mode``): ``NEXT_STEP`` (default: a world that ended is reset by the
    following ``step``, which returns its first observation with zero reward), ``SAME_STEP`` (reset
    inside the ending step; its last observation and info go to ``info["final_obs"]`` and
    ``info["final_info"]``), ``DISABLED`` (reset with ``reset(options={"reset_mask": mask})``; other
    worlds stay bit-identical). ``info`` holds arrays [N] (``goal``: [N, 3]) with ``_key`` masks.
    Every world (re)set by ``reset`` or by an autoreset in ``step`` gets a ``ReplaySpec`` in
    ``info["replay_spec"]`` (object array [N], mask ``info["_replay_spec"]``): the seed or RNG state,
    options, object, material and pose with which a single env repeats that world's episode start.
    ``torch_outputs=True`` returns observations (float32; pixels uint8), reward (float32 [N]),
    terminated and truncated (bool [N]) as torch tensors on the simulation's device, made there
    from the task's device outputs (``PickupTask``: observations, reward and flags are computed by
    Warp kernels on that device, not uploaded from the host; pixels are rendered on the host);
    ``info`` stays numpy (one download of the step's outputs a step, which the resets need anyway).
    ``step`` also takes the actions as a torch tensor (copied to the host and uploaded once).
    ``full_state_torch()`` gives the complete FEM state as zero-copy torch views of the simulation's
    own arrays (on the GPU when ``device="cuda:0"``): node positions/velocities/forces [N, 3] and
    von Mises stress [T] of all worlds, with ``model.node_start`` / ``model.tet_start`` offsets (a
    world's object rows: ``model.world_nodes(w)`` / ``world_tets(w)``; slotted worlds' spare rows follow).
    ``render_mode="human"``: the 3D browser view of one world (``viewer_world``, default 0) at every
    reset and step, served on ``viewer_host``/``viewer_port`` as for the single env.
    """

    def __init__(self, num_envs: int = 1, max_episode_steps: int | None = None, render_mode: str | None = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, torch_outputs: bool = False,
                 config: PickupConfig | None = None, viewer_world: int = 0, viewer_host: str = "127.0.0.1",
                 viewer_port: int = 8080, world_objects: Sequence[str] | None = None, **kwargs: Any):
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        self.config = make_config(config, kwargs)
        #: the object each world holds in every episode (``world_objects``), or None: drawn per episode
        self.world_objects = check_world_objects(world_objects, num_envs, self.config.object_names)
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ValueError(f"autoreset_mode must be one of {[m.value for m in AutoresetMode]}, "
                             f"got {autoreset_mode!r}") from None
        if render_mode not in (None, "rgb_array", "human"):
            raise ValueError(f"render_mode must be None, 'rgb_array' or 'human', got {render_mode!r}")
        self.num_envs = num_envs
        self.render_mode = render_mode
        self._viewer, self._viewer_world = None, viewer_world
        if render_mode == "human":
            if isinstance(viewer_world, bool) or not isinstance(viewer_world, int) or not 0 <= viewer_world < num_envs:
                raise ValueError(f"viewer_world must be an int in [0, {num_envs - 1}], got {viewer_world!r}")
            from ..viewer import LiveSceneViewer, check_port_free

            check_port_free(viewer_host, viewer_port, "viewer_port")
            self._viewer = LiveSceneViewer(host=viewer_host, port=viewer_port)
        self.max_episode_steps = max_episode_steps if max_episode_steps is not None else self.config.max_episode_steps
        self.metadata = {"render_modes": ["rgb_array", "human"], "render_fps": render_fps(self.config.control_hz),
                         "autoreset_mode": self.autoreset_mode}
        self.single_observation_space = observation_spaces(self.config)
        self.single_action_space = action_space(self.config)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.torch_outputs = bool(torch_outputs)
        self._rngs = [seeding.np_random(None)[0] for _ in range(num_envs)]
        self.scene: PickupScene | None = None
        #: the task's observations, reward and flags on the simulation's device (made at the first reset)
        self.task: PickupTask | None = None
        self._decoder: DeviceActionDecoder | None = None  # the actions' decoding on the device (the same)
        self._needs_reset = np.zeros(num_envs, bool)
        self._origins = [None] * num_envs  # each world's ReplaySpec of the reset that built its object
        self._camera = SceneCamera(self.config)

    # -- gym API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        mask = np.ones(self.num_envs, bool)
        unknown = sorted(set(options or {}) - {"reset_mask"})
        if unknown:
            raise ValueError(f"vector reset options must be a subset of ['reset_mask'], got {unknown}")
        if options is not None and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"])
            if mask.shape != (self.num_envs,) or mask.dtype != bool:
                raise ValueError(f"reset_mask must be a bool array of shape ({self.num_envs},), "
                                 f"got {mask.dtype} {mask.shape}")
        seeds = world_seeds(seed, self.num_envs)
        for i in np.flatnonzero(mask):
            if seeds[i] is not None or self.scene is None:
                self._rngs[i] = seeding.np_random(seeds[i])[0]
        info = {"is_success": np.zeros(self.num_envs, bool), "_is_success": mask.copy(),
                **self._reset_worlds(mask, seeds)}
        if self._viewer is not None:
            if mask[self._viewer_world]:
                self._viewer.new_episode()
            self.render()
        return self._obs(), info

    def step(self, actions):
        if self.scene is None:
            raise RuntimeError("call reset() before step()")
        n = self.num_envs
        if hasattr(actions, "detach"):  # a torch tensor (on any device)
            actions = actions.detach().cpu().numpy()
        a = check_actions(actions, (n,) + self.single_action_space.shape, self.single_action_space.low,
                          self.single_action_space.high)
        resetting = self._needs_reset.copy() if self.autoreset_mode == AutoresetMode.NEXT_STEP else np.zeros(n, bool)
        self._decoder.decode(self.scene.gripper, a)  # the targets, on the device
        stats = self.scene.step_to_gripper_targets(active=~resetting)
        self.task.evaluate(self.scene, live=~resetting, max_episode_steps=self.max_episode_steps)  # on the device
        result = self.task.result()  # the one download of the step's outputs
        terminated, truncated, reward = result["terminated"], result["truncated"], result["reward"]
        info = step_infos(result, stats)
        live = ~resetting
        info = {**info, **{f"_{k}": live.copy() for k in list(info)}}
        done = terminated | truncated
        if resetting.any():
            # after the step: the worlds' frozen-gripper step is discarded, and their first
            # observation is the state the reset sets, as a single env's reset returns it
            info.update(self._reset_worlds(resetting))
        obs = self._obs(_STEP_RESULT)  # a reset rewrites the observation columns only
        if self.torch_outputs:
            reward, terminated, truncated = (obs.pop(name) for name in _STEP_RESULT)
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._needs_reset = done
        elif self.autoreset_mode == AutoresetMode.SAME_STEP and done.any():
            info["final_obs"] = obs
            info["final_info"] = {k: v.copy() for k, v in info.items() if k not in ("final_obs",)}
            info["_final_obs"] = done.copy()
            info["_final_info"] = done.copy()
            info.update(self._reset_worlds(done))
            obs = self._obs()
        if self._viewer is not None:
            self.render()
        return obs, reward, terminated, truncated, info

    def render(self):
        if self.render_mode == "human" and self.scene is not None:
            w = self._viewer_world
            self._viewer.show(self.scene, w, self.task.goal(w), time_s=float(self.task.elapsed[w]) * self.config.dt)
        if self.render_mode != "rgb_array":
            return None
        return np.stack([self._render_world(w) for w in range(self.num_envs)])

    def full_state_torch(self) -> dict:
        """Zero-copy torch views of the FEM state of all worlds (world frame, SI units): valid until
        the next ``step``/``reset`` writes into them; copy what must be kept."""
        if self.scene is None:
            raise RuntimeError("call reset() before full_state_torch()")
        st = self.scene.state
        return {name: wp.to_torch(getattr(st, name)) for name in (
            "positions", "velocities", "elastic_force", "contact_force", "von_mises", "mean_von_mises",
            "pad_normal_force")}

    def close_extras(self, **kwargs):
        if self._viewer is not None:
            self._viewer.close()
        self.scene = None
        self._camera = SceneCamera(self.config)

    # -- internals -------------------------------------------------------------------------
    def _reset_worlds(self, mask: np.ndarray, seeds: list | None = None) -> dict[str, np.ndarray]:
        """Reset the worlds in ``mask`` (all of them when the scene is built) from their RNGs, just
        seeded with ``seeds[w]`` where that is not None. Returns the reset info entries of the reset
        worlds: ``replay_spec`` (object array [N]), ``object`` (object array [N]),
        ``youngs_modulus`` [N] Pa, ``goal`` [N, 3] m (a row per world), each with its ``_key`` mask."""
        seeds = seeds if seeds is not None else [None] * self.num_envs
        built = self.scene is None
        reset = np.ones(self.num_envs, bool) if built else mask
        specs = np.full(self.num_envs, None, dtype=object)
        setups = [None] * self.num_envs
        for w in np.flatnonzero(reset):
            # a world outside the mask is drawn (at the build) from an RNG that was not reseeded
            fixed = None if self.world_objects is None else self.world_objects[w]
            setups[w], spec = draw_world(self.config, self._rngs[w], seeds[w] if mask[w] else None, fixed,
                                         None if fixed is None else {"object": fixed})
            if built or setups[w].object_name != self.scene.object_names[w]:
                self._origins[w] = spec  # this reset builds the world's object
                specs[w] = spec
            else:
                specs[w] = dataclasses.replace(spec, scene_origin=self._origins[w])
        if built:
            # fixed objects never change a world's rows: packed (no spare rows to step)
            self.scene = PickupScene(self.config, setups, slotted=False if self.world_objects is not None else None)
        else:
            self.scene.reset_worlds(mask, setups)
        if self.task is None:
            self.task = PickupTask(self.config, self.num_envs, self.max_episode_steps)
            self._decoder = DeviceActionDecoder(self.config, self.num_envs)
        objects = np.full(self.num_envs, None, dtype=object)
        moduli = np.zeros(self.num_envs)
        goals = np.zeros((self.num_envs, 3))
        for w in np.flatnonzero(reset):
            objects[w], moduli[w], goals[w] = setups[w].object_name, setups[w].material.youngs_modulus, setups[w].goal
        self.task.reset(reset, goals)  # at the build: every world (all drew), else the mask
        self.task.observe(self.scene)
        self._needs_reset[mask] = False
        return {"replay_spec": specs, "_replay_spec": reset.copy(), "object": objects, "_object": reset.copy(),
                "youngs_modulus": moduli, "_youngs_modulus": reset.copy(), "goal": goals, "_goal": reset.copy()}

    def _obs(self, result_names: tuple[str, ...] = ()):
        """The observation dict; with ``torch_outputs`` also the step result columns
        ``result_names`` as tensors (``PickupTask.torch_outputs``: one conversion a step)."""
        pixels = None
        if "pixels" in self.single_observation_space.spaces:
            pixels = np.stack([self._render_world(w) for w in range(self.num_envs)])
        if not self.torch_outputs:
            return observations(self.task, pixels)
        obs = self.task.torch_outputs(result_names)
        if pixels is not None:
            import torch

            obs["pixels"] = torch.from_numpy(pixels).to(wp.device_to_torch(self.task.device))
        return obs

    def _render_world(self, w: int) -> np.ndarray:
        return self._camera.render(self.scene, w, self.task.goal(w))
