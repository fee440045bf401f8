"""Human-like device streams from a gripper trajectory: the retargeting (eq. 1-4) run backwards.

Used to make the recorded operator streams in ``tests/data`` (end-to-end test, benchmark, demos of
``defgrasp-teleop --tracker replay:... --glove replay:...``):

1. ``expert_trajectory``: run ``ScriptedPickupExpert`` (delta actions) once and keep, per control
   step k, the command it gave: flange pose after the step (m, quaternion xyzw, world) and the jaw
   target gap (m); a still period before and a hold after are added, as an operator would;
2. ``synthesize_streams``: invert the retargeting -
   * eq. 1-2: with the offset calibrated on the first step, T_slave = S_0 (M_0 X)^-1 T_master X,
     so the tracker pose that makes the flange reach T_slave is
     T_master = M_0 X S_0^-1 T_slave X^-1 (M_0: the operator's hand pose at calibration in the
     OpenVR frame, S_0: the gripper at reset, X: ``tracker_to_flange``);
   * eq. 4: gap -> pinch distance D through the inverse of the calibrated ``PinchGapMap``, then
     D -> glove joint angles along a thumb-index pinch path (``PinchPath``: finger-URDF FK of a
     joint-space line from the open hand to a tip-to-tip pinch, inverted by interpolation); the
     SDK fingertips are the FK of those angles;
   * human-like imperfections (``OperatorModel``): slow drift and tremor of the hand, tracker
     jitter, joint-angle noise, sample-time jitter, lost datagrams and one tracking dropout
     (samples with ``valid = False``) during which the operator, seeing the gripper stop, waits
     (the trajectory's clock stands still and resumes after it).

Regenerate the test data with ``python -m teleop.testing.synth --out tests/data`` (runs the env once).
"""

from __future__ import annotations

import argparse
import json
import pathlib
from dataclasses import asdict, dataclass, field

import numpy as np

from .._validate import check_array, check_number
from ..sensors.base import GloveSample, TrackerSample
from ..sensors.recorder import StreamRecorder
from ..retarget.pinch import INDEX, THUMB, PinchGapMap
from ..se3 import invert, pose_to_matrix, quat_slerp, rotvec_to_quat

#: Tip-to-tip pinch of the default ``HandGeometry`` (rad, [5, 4]; thumb and index from a
#: minimisation of D, the other fingers curled along as a relaxed hand does).
PINCH_ANGLES = (
    (-0.07, 0.835, 0.274, -0.015),
    (-0.004, 0.818, 0.565, 1.034),
    (0.0, 0.75, 0.75, 0.5),
    (0.0, 0.8, 0.8, 0.5),
    (0.0, 0.85, 0.8, 0.5),
)


@dataclass(frozen=True)
class GripperTrajectory:
    """Flange commands at the control rate: step k holds at stream time k * dt.

    position [K, 3] m and quat_xyzw [K, 4] (world, y up), gap_m [K] jaw target; reset_pose: the
    gripper's pose at reset (S_0, 4x4); seed/env_kwargs: the episode it was made for;
    success_step: the expert's success step (index into the arrays) or None.
    """

    dt: float
    position: np.ndarray
    quat_xyzw: np.ndarray
    gap_m: np.ndarray
    reset_pose: np.ndarray
    seed: int
    env_kwargs: dict
    success_step: int | None

    @property
    def duration_s(self) -> float:
        return (len(self.gap_m) - 1) * self.dt

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, float]:
        """(position, quaternion, gap) at stream time ``t`` (s): linear / slerp interpolation."""
        s = float(np.clip(t / self.dt, 0.0, len(self.gap_m) - 1))
        i = min(int(s), len(self.gap_m) - 2)
        f = s - i
        p = (1 - f) * self.position[i] + f * self.position[i + 1]
        q = quat_slerp(self.quat_xyzw[i], self.quat_xyzw[i + 1], f)
        g = (1 - f) * self.gap_m[i] + f * self.gap_m[i + 1]
        return p, q, float(g)


def _jaw_target(jaw_action: float) -> float:
    """Delta-mode jaw command in [-1, 1] -> its target gap (m), as the env maps it."""
    from defgrasp_env.gripper import GAP_MAX, GAP_MIN

    return float(GAP_MAX - (np.clip(jaw_action, -1, 1) + 1.0) / 2.0 * (GAP_MAX - GAP_MIN))


def expert_trajectory(env_kwargs: dict | None = None, *, seed: int = 0, still_s: float = 0.5, hold_s: float = 1.5,
                      max_steps: int = 300) -> GripperTrajectory:
    """Run the scripted expert once (delta mode) and return its commands (module doc, step 1)."""
    import gymnasium as gym

    import defgrasp_env  # noqa: F401  (registers the env)
    from defgrasp_env.policies import ScriptedPickupExpert

    kwargs = {k: v for k, v in (env_kwargs or {}).items() if k != "action_mode"}
    env = gym.make("DeformablePickup-v0", **kwargs)
    try:
        expert = ScriptedPickupExpert.from_env(env)
        obs, _ = env.reset(seed=seed)
        expert.reset()
        dt = env.unwrapped.config.dt
        a0 = np.asarray(obs["agent_pos"], np.float64)
        pos, quat, gap = [a0[:3]], [a0[3:7] / np.linalg.norm(a0[3:7])], [float(a0[7])]
        success = None
        for _ in range(max_steps):
            action = expert(obs)
            obs, _, terminated, truncated, info = env.step(action)
            a = np.asarray(obs["agent_pos"], np.float64)
            pos.append(a[:3])
            quat.append(a[3:7] / np.linalg.norm(a[3:7]))
            gap.append(_jaw_target(float(action[6])))
            if terminated or truncated:
                success = len(gap) - 1 if info["is_success"] else None
                break
    finally:
        env.close()
    n_still, n_hold = int(round(still_s / dt)), int(round(hold_s / dt))
    pos = [pos[0]] * n_still + pos + [pos[-1]] * n_hold
    quat = [quat[0]] * n_still + quat + [quat[-1]] * n_hold
    gap = [gap[0]] * n_still + gap + [gap[-1]] * n_hold
    return GripperTrajectory(
        dt, np.array(pos), np.array(quat), np.array(gap), pose_to_matrix(pos[0], quat[0]), int(seed), dict(kwargs),
        None if success is None else success + n_still,
    )


def distance_for_gap(gap_map: PinchGapMap, gap_m: float) -> float:
    """Inverse of ``PinchGapMap.gap`` on its linear part: the pinch distance D (m) giving ``gap_m``."""
    m = gap_map
    s = (gap_m - m.gap_closed_m) / (m.gap_open_m - m.gap_closed_m)
    return float(m.d_closed_m + s * (m.d_open_m - m.d_closed_m))


class PinchPath:
    """Glove joint angles along a line in joint space from the open hand (s = 0) to the pinch
    (s = 1, ``PINCH_ANGLES``); ``angles_for_distance(D)`` inverts D(s) (finger-URDF FK)."""

    def __init__(self, kinematics=None, pinch_angles=PINCH_ANGLES, samples: int = 401):
        from ..retarget.pinch import FingerKinematics

        self.kinematics = kinematics or FingerKinematics()
        self.pinch = check_array("pinch_angles", pinch_angles, (5, 4), lo=-np.pi, hi=np.pi, unit="rad")
        self.s = np.linspace(0.0, 1.0, samples)
        tips = self.kinematics.fingertip_positions(self.s[:, None, None] * self.pinch[None])
        self.distance = np.linalg.norm(tips[:, THUMB] - tips[:, INDEX], axis=1)
        if np.any(np.diff(self.distance) >= 0):
            raise ValueError("the pinch path must close the thumb-index distance monotonically; check pinch_angles")

    @property
    def range_m(self) -> tuple[float, float]:
        """(smallest, largest) pinch distance D reachable on the path (m)."""
        return float(self.distance[-1]), float(self.distance[0])

    def angles_for_distance(self, d_m: float) -> np.ndarray:
        """Joint angles [5, 4] (rad) with thumb-index distance ``d_m`` (clamped to ``range_m``)."""
        s = float(np.interp(d_m, self.distance[::-1], self.s[::-1]))
        return s * self.pinch


@dataclass(frozen=True)
class OperatorModel:
    """How the synthetic operator moves and how the devices sample (SI units, rad).

    master_position / master_rotvec: the hand (tracker) pose at calibration in the OpenVR frame;
    drift_m: std of the slow hand drift (low-passed at drift_hz); tremor_m: white tracker jitter;
    rot_jitter_rad / rot_drift_rad: the same for orientation; joint_noise_rad: glove angles;
    tip_noise_m: SDK fingertips; time_jitter_s: sample-time jitter; drop_fraction: datagrams
    lost; dropout_start_s / dropout_s: one tracking loss (``valid = False``; the operator waits
    it out); open_hand_m: the pinch distance of the relaxed open hand (wider than the calibrated
    open end); squeeze_m: the operator pinches this much tighter than the trajectory's gap once
    the jaw is closing (a human grips firmer than the expert's gentle squeeze; the gripper's force
    limit caps the grip).
    """

    master_position: tuple = (0.15, 1.05, -0.35)
    master_rotvec: tuple = (-0.35, 0.4, 0.1)
    tracker_hz: float = 60.0
    glove_hz: float = 50.0
    drift_m: float = 0.0008
    drift_hz: float = 0.8
    tremor_m: float = 0.0003
    rot_jitter_rad: float = 0.003
    rot_drift_rad: float = 0.006
    joint_noise_rad: float = 0.006
    tip_noise_m: float = 0.0005
    time_jitter_s: float = 0.002
    drop_fraction: float = 0.01
    dropout_start_s: float | None = 1.45
    dropout_s: float = 0.25
    open_hand_m: float = 0.108
    squeeze_m: float = 0.004
    seed: int = 1
    tracker_to_flange: tuple | None = None
    gap_map: PinchGapMap = field(default_factory=PinchGapMap)

    def __post_init__(self):
        check_array("master_position", self.master_position, (3,), unit="m")
        check_array("master_rotvec", self.master_rotvec, (3,), unit="rad")
        for name in ("tracker_hz", "glove_hz", "drift_hz"):
            check_number(name, getattr(self, name), 0.0, 1000.0, unit="Hz", lo_open=True)
        for name in ("drift_m", "tremor_m", "tip_noise_m"):
            check_number(name, getattr(self, name), 0.0, 0.05, unit="m")
        for name in ("rot_jitter_rad", "rot_drift_rad", "joint_noise_rad"):
            check_number(name, getattr(self, name), 0.0, 0.5, unit="rad")
        check_number("time_jitter_s", self.time_jitter_s, 0.0, 0.01, unit="s")
        check_number("drop_fraction", self.drop_fraction, 0.0, 0.5)
        if self.dropout_start_s is not None:
            check_number("dropout_start_s", self.dropout_start_s, 0.0, unit="s")
        check_number("dropout_s", self.dropout_s, 0.0, 5.0, unit="s")
        check_number("open_hand_m", self.open_hand_m, 0.0, 0.5, unit="m")
        check_number("squeeze_m", self.squeeze_m, 0.0, 0.085, unit="m")
        if not isinstance(self.gap_map, PinchGapMap):
            raise TypeError(f"gap_map must be a PinchGapMap, got {self.gap_map!r}")


def _smooth_noise(rng: np.random.Generator, n: int, dims: int, rate_hz: float, cutoff_hz: float, std: float) -> np.ndarray:
    """Low-passed white noise [n, dims] with standard deviation ``std`` (two first-order passes)."""
    if std == 0.0 or n == 0:
        return np.zeros((n, dims))
    a = 1.0 - np.exp(-2.0 * np.pi * cutoff_hz / rate_hz)
    x = rng.standard_normal((n + int(5 * rate_hz / cutoff_hz), dims))
    for _ in range(2):
        y = np.empty_like(x)
        acc = np.zeros(dims)
        for i in range(len(x)):
            acc = acc + a * (x[i] - acc)
            y[i] = acc
        x = y
    x = x[-n:]
    return x / max(float(x.std()), 1e-12) * std


def _sample_times(rng, duration_s: float, rate_hz: float, jitter_s: float, drop: float) -> np.ndarray:
    t = np.arange(0.0, duration_s + 1e-9, 1.0 / rate_hz)
    t = t + rng.uniform(-jitter_s, jitter_s, t.shape) * (np.arange(len(t)) > 0)
    keep = rng.random(len(t)) >= drop
    keep[0] = True
    return np.maximum.accumulate(np.clip(t[keep], 0.0, None))


def synthesize_streams(traj: GripperTrajectory, model: OperatorModel | None = None, *, pinch_path: PinchPath | None = None
                       ) -> tuple[list[TrackerSample], list[GloveSample]]:
    """Tracker and glove samples (stream time from 0 s) that drive the gripper along ``traj``
    through ``HumanTeleopAgent`` calibrated on its first step (module doc, step 2)."""
    m = model or OperatorModel()
    path = pinch_path or PinchPath()
    rng = np.random.default_rng(m.seed)
    M0 = pose_to_matrix(m.master_position, rotvec_to_quat(m.master_rotvec))
    X = np.eye(4) if m.tracker_to_flange is None else np.asarray(m.tracker_to_flange, np.float64)
    base = M0 @ X @ invert(traj.reset_pose)
    X_inv = invert(X)

    pause = 0.0 if m.dropout_start_s is None else m.dropout_s
    t0_lost = np.inf if m.dropout_start_s is None else m.dropout_start_s

    def traj_time(t: float) -> float:  # the operator waits while the tracker is lost
        return min(t, t0_lost) + max(0.0, t - t0_lost - pause)

    duration = traj.duration_s + pause
    t_tr = _sample_times(rng, duration, m.tracker_hz, m.time_jitter_s, m.drop_fraction)
    drift = _smooth_noise(rng, len(t_tr), 3, m.tracker_hz, m.drift_hz, m.drift_m)
    rdrift = _smooth_noise(rng, len(t_tr), 3, m.tracker_hz, m.drift_hz, m.rot_drift_rad)
    trackers, last_valid = [], M0
    for i, t in enumerate(t_tr):
        p, q, _ = traj.at(traj_time(t))
        T = base @ pose_to_matrix(p, q) @ X_inv
        R = pose_to_matrix(np.zeros(3), rotvec_to_quat(rdrift[i] + rng.normal(0.0, m.rot_jitter_rad, 3)))
        T = T @ R  # hand-frame wobble
        T[:3, 3] += drift[i] + rng.normal(0.0, m.tremor_m, 3)
        lost = t0_lost <= t < t0_lost + pause
        if not lost:
            last_valid = T
        trackers.append(TrackerSample(last_valid, not lost, float(t)))

    t_gl = _sample_times(rng, duration, m.glove_hz, m.time_jitter_s, m.drop_fraction)
    jdrift = _smooth_noise(rng, len(t_gl), 20, m.glove_hz, m.drift_hz, m.joint_noise_rad)
    gap_open = m.gap_map.gap_open_m
    gloves = []
    for i, t in enumerate(t_gl):
        _, _, gap = traj.at(traj_time(t))
        d = m.open_hand_m if gap >= gap_open - 1e-4 else distance_for_gap(m.gap_map, gap - m.squeeze_m)
        angles = path.angles_for_distance(d) + jdrift[i].reshape(5, 4) + rng.normal(0.0, m.joint_noise_rad / 2, (5, 4))
        tips = path.kinematics.fingertip_positions(angles) + rng.normal(0.0, m.tip_noise_m, (5, 3))
        gloves.append(GloveSample(angles, tips, True, float(t)))
    return trackers, gloves


def write_streams(directory, name: str, traj: GripperTrajectory, model: OperatorModel,
                  trackers: list[TrackerSample], gloves: list[GloveSample]) -> dict[str, pathlib.Path]:
    """Write ``<name>_tracker.jsonl``, ``<name>_glove.jsonl`` and ``<name>.json`` (episode and
    operator metadata) to ``directory``; returns the paths."""
    d = pathlib.Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    paths = {"tracker": d / f"{name}_tracker.jsonl", "glove": d / f"{name}_glove.jsonl", "meta": d / f"{name}.json"}
    for kind, samples in (("tracker", trackers), ("glove", gloves)):
        with StreamRecorder(paths[kind], kind, overwrite=True) as rec:
            for s in samples:
                rec.append(s)
    op = asdict(model)
    op["gap_map"] = asdict(model.gap_map)
    meta = {
        "description": "synthetic operator (scripted expert retargeted backwards, human-like noise); "
                       "made by python -m teleop.testing.synth",
        "seed": traj.seed, "env_kwargs": traj.env_kwargs, "dt": traj.dt,
        "duration_s": max(trackers[-1].timestamp_s, gloves[-1].timestamp_s),
        "expert_success_time_s": None if traj.success_step is None else traj.success_step * traj.dt,
        "dropout_s": [model.dropout_start_s, model.dropout_s] if model.dropout_start_s is not None else None,
        "operator": op,
    }
    paths["meta"].write_text(json.dumps(meta, indent=1) + "\n", encoding="utf-8")
    return paths


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m teleop.testing.synth", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="tests/data", help="output folder (default tests/data)")
    p.add_argument("--name", default="human_pick_cuboid", help="file name stem")
    p.add_argument("--object", default="cuboid")
    p.add_argument("--youngs-modulus", type=float, default=1e5, help="Pa")
    p.add_argument("--seed", type=int, default=0, help="env reset seed of the episode")
    p.add_argument("--operator-seed", type=int, default=1, help="seed of the operator noise")
    args = p.parse_args(argv)
    traj = expert_trajectory({"object": args.object, "youngs_modulus": args.youngs_modulus}, seed=args.seed)
    if traj.success_step is None:
        print("warning: the expert did not succeed on this episode; the stream replays its attempt")
    model = OperatorModel(seed=args.operator_seed)
    trackers, gloves = synthesize_streams(traj, model)
    paths = write_streams(args.out, args.name, traj, model, trackers, gloves)
    for k, v in paths.items():
        print(f"{k}: {v} ({v.stat().st_size / 1024:.0f} KiB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
