"""Read what an episode file stores out of a ``PickupScene`` (one world), as numpy copies.

Per step only copies are taken, plus the flange forward kinematics: the sums and stacking happen
once per episode in :class:`EpisodeBuffer`, which keeps the per-step overhead of recording small.
"""

from __future__ import annotations

import numpy as np

from ..envs.scene import PickupScene

def object_record(scene: PickupScene, w: int = 0) -> dict[str, np.ndarray]:
    """The ``object/`` group of world ``w`` (initial pose, material and mesh: local node indices)
    and its episode's ``task/goal`` (m, world) where the reset drew one."""
    setup = scene.setups[w]
    mat = scene.materials[w]
    mesh = scene.mesh(w)
    m = scene.model
    tets = m.tets.numpy()[m.world_tets(w)] - int(m.node_start[w])
    goal = {} if setup.goal is None else {"task/goal": np.asarray(setup.goal, dtype=np.float64).copy()}
    return {
        **goal,
        "object/initial_position": np.asarray(setup.position, dtype=np.float64).copy(),
        "object/initial_quaternion": np.asarray(setup.quat, dtype=np.float64).copy(),
        "object/density": np.float64(mat.density),
        "object/youngs_modulus": np.float64(mat.youngs_modulus),
        "object/poisson_ratio": np.float64(mat.poisson_ratio),
        "object/triangles": np.asarray(m.surfaces[w], dtype=np.int32).copy(),
        "object/tetrahedra": np.ascontiguousarray(tets, dtype=np.int32),
        "object/rest_nodes": np.asarray(mesh.nodes, dtype=np.float64).copy(),
    }


def step_records(scene: PickupScene, worlds) -> list[tuple]:
    """The raw per-step state of each world in ``worlds``: node positions, velocities, elastic and
    contact forces, von Mises stress, mean von Mises, flange position and orientation, jaw gap,
    tip forces. Each simulation array is read from the device once for all the worlds."""
    m, s = scene.model, scene.state
    x, v, fe, fc = (a.numpy() for a in (s.positions, s.velocities, s.elastic_force, s.contact_force))
    vm, mvm = s.von_mises.numpy(), s.mean_von_mises.numpy()
    gripper = scene.gripper
    pos, quat = gripper.flange_pose()
    rows = []
    for w in worlds:
        nodes, tets = m.world_nodes(w), m.world_tets(w)
        rows.append((x[nodes].copy(), v[nodes].copy(), fe[nodes].copy(), fc[nodes].copy(), vm[tets].copy(),
                     mvm[w].copy(), pos[w].copy(), quat[w].copy(), float(gripper.gap[w]), gripper.tip_force[w].copy()))
    return rows


def step_record(scene: PickupScene, w: int = 0) -> tuple:
    """``step_records`` of one world."""
    return step_records(scene, [w])[0]


class EpisodeBuffer:
    """In-memory rows of one episode until it is written."""

    def __init__(self, obj: dict[str, np.ndarray], obs0: dict, dt: float):
        self.object = obj
        self.dt = dt
        self.rows: list[tuple] = []
        self.actions: list[np.ndarray] = []
        self.rewards: list[float] = []
        self.terminated: list[bool] = []
        self.truncated: list[bool] = []
        self.infos: list[dict] = []
        self.observations: dict[str, list[np.ndarray]] = {k: [np.array(v, copy=True)] for k, v in obs0.items()}

    def __len__(self) -> int:
        return len(self.rows)

    def append(self, row: tuple, action, obs: dict, reward: float, terminated: bool, truncated: bool,
               info: dict) -> None:
        self.rows.append(row)
        self.actions.append(np.array(action, dtype=np.float64, copy=True))
        self.rewards.append(float(reward))
        self.terminated.append(bool(terminated))
        self.truncated.append(bool(truncated))
        self.infos.append(info)
        for k, v in obs.items():
            self.observations.setdefault(k, []).append(np.array(v, copy=True))

    def _info_arrays(self) -> dict[str, np.ndarray]:
        """``info/<key>`` for scalar entries present in every step (bool, int or float)."""
        if not self.infos:
            return {}
        out = {}
        for key in self.infos[0]:
            values = [i.get(key) for i in self.infos]
            if all(isinstance(v, (bool, np.bool_)) for v in values):
                out[f"info/{key}"] = np.array(values, dtype=bool)
            elif all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in values):
                out[f"info/{key}"] = np.array(values, dtype=np.int64)
            elif all(isinstance(v, (int, float, np.number)) and not isinstance(v, bool) for v in values):
                out[f"info/{key}"] = np.array(values, dtype=np.float64)
        return out

    def arrays(self) -> dict[str, np.ndarray]:
        """Every dataset of the episode file ("group/name" -> array)."""
        if not self.rows:
            raise ValueError("an episode needs at least one step to be written")
        cols = [np.stack(c) if isinstance(c[0], np.ndarray) else np.array(c) for c in zip(*self.rows)]
        x, v, fe, fc, vm, mvm, wpos, wquat, gap, tips = cols
        t = len(self.rows)
        out = dict(self.object)
        out.update({
            "steps/time": (np.arange(1, t + 1, dtype=np.float64) * self.dt),
            "steps/node_positions": x.astype(np.float32),
            "steps/node_forces": (fe + fc).astype(np.float32),
            "steps/von_mises": vm.astype(np.float32),
            "steps/mean_von_mises": mvm.astype(np.float32),
            "steps/wrist_position": wpos.astype(np.float64),
            "steps/wrist_orientation": wquat.astype(np.float64),
            "steps/jaw_length": gap.astype(np.float64),
            "steps/left_tip_normal_force": tips[:, 0].astype(np.float64),
            "steps/right_tip_normal_force": tips[:, 1].astype(np.float64),
            "steps/node_velocities": v.astype(np.float32),
            "steps/contact_forces": fc.astype(np.float32),
            "steps/action": np.stack(self.actions).reshape(t, -1),
            "steps/reward": np.array(self.rewards, dtype=np.float64),
            "steps/terminated": np.array(self.terminated, dtype=bool),
            "steps/truncated": np.array(self.truncated, dtype=bool),
            "steps/is_success": np.array([bool(i.get("is_success", False)) for i in self.infos], dtype=bool),
        })
        for key, values in self.observations.items():
            out[f"observations/{key}"] = np.stack(values)
        out.update(self._info_arrays())
        return out
