"""End to end: a recorded human-like operator stream, sent over loopback UDP to the real receivers,
drives ``HumanTeleopAgent`` -> ``DeformablePickup-v0`` (absolute actions) to success, and the
haptic commands come back to the sending side.

The stream (``tests/data/human_pick_cuboid_*.jsonl``, made by ``python -m teleop.testing.synth``) is
the scripted expert's pick of the cuboid (seed 0) retargeted backwards - tracker poses through the
inverse of the calibrated offset (eq. 1-2), glove joint angles through the inverse pinch map and
the finger FK (eq. 4) - with hand drift and tremor, tracker jitter, glove noise, sample-time jitter,
lost datagrams and a 0.25 s tracking dropout while the jaw closes (the operator waits it out).

Replay is lock-step: before control step k, every sample whose stream time is <= k * dt is sent
(60 Hz tracker, 50 Hz glove: 2-3 datagrams per step; the receivers keep the newest). So the loop
runs as fast as this machine allows, yet sees what an operator would have produced by then.
"""

import json
import pathlib
import time

import numpy as np
import pytest

DATA = pathlib.Path(__file__).parent / "data"
STREAM = "human_pick_cuboid"


@pytest.fixture(scope="module")
def meta():
    return json.loads((DATA / f"{STREAM}.json").read_text())


def test_stream_files_are_small_and_valid(meta):
    from teleop.sensors import load_stream

    tr, gl = load_stream(DATA / f"{STREAM}_tracker.jsonl"), load_stream(DATA / f"{STREAM}_glove.jsonl")
    assert tr.kind == "tracker" and gl.kind == "glove"
    assert sum(p.stat().st_size for p in DATA.glob(f"{STREAM}*")) < 1_000_000
    lost = [s.timestamp_s for s in tr.samples if not s.valid]
    t0, dur = meta["dropout_s"]
    assert lost and min(lost) >= t0 - 0.02 and max(lost) <= t0 + dur + 0.02  # exactly one dropout
    rate = (len(tr.samples) - 1) / (tr.samples[-1].timestamp_s - tr.samples[0].timestamp_s)
    assert 55 < rate < 62  # 60 Hz minus a few lost datagrams


def test_udp_operator_stream_picks_the_object(meta):
    import gymnasium as gym

    import defgrasp_env  # noqa: F401
    from defgrasp_env.layout import ENV_STATE
    from teleop import HumanTeleopAgent, HumanTeleopConfig, UdpGloveReceiver, UdpTrackerReceiver
    from teleop.testing.udp_replay import StreamPlayer
    from teleop.retarget import RateLimits

    env = gym.make("DeformablePickup-v0", action_mode="absolute", **meta["env_kwargs"])
    dt = env.unwrapped.config.dt
    assert dt == pytest.approx(meta["dt"])
    rt, rg = UdpTrackerReceiver("127.0.0.1", 0), UdpGloveReceiver("127.0.0.1", 0)
    agent = HumanTeleopAgent(rt, rg, HumanTeleopConfig(limits=RateLimits(dt=dt)))  # default: iterative IK (eq. 3)
    agent.connect()
    player = StreamPlayer(DATA / f"{STREAM}_tracker.jsonl", DATA / f"{STREAM}_glove.jsonl",
                          tracker_address=rt.address, glove_address=rg.address)
    obs, info = env.reset(seed=meta["seed"])
    agent.reset()
    y0 = float(ENV_STATE.get(obs["environment_state"], "feature_position")[1])
    statuses, actions, heights, step_s = [], [], [], []
    terminated = truncated = False
    try:
        for k in range(env.spec.max_episode_steps):
            t0 = time.perf_counter()
            player.advance_to(k * dt)
            action = agent.act(obs)
            obs, _, terminated, truncated, info = env.step(action)
            agent.send_feedback(info)
            player.poll_haptics()
            step_s.append(time.perf_counter() - t0)
            statuses.append(agent.status)
            actions.append(action)
            heights.append(float(ENV_STATE.get(obs["environment_state"], "feature_position")[1]))
            if terminated or truncated:
                break
        time.sleep(0.02)
        player.poll_haptics()  # the last step's command
    finally:
        player.close()
        agent.disconnect()
        env.close()

    lift = max(heights) - y0
    why = (f"success={info['is_success']} after {k + 1} steps; feature point rose {lift:.3f} m "
           f"(final {heights[-1]:.3f} m, goal 0.6 m); statuses {''.join(s[0] for s in statuses)}")
    assert terminated and info["is_success"], why
    assert lift > 0.5, why

    # the tracking dropout: held (no motion), then resumed once without a jump
    assert statuses.count("hold") >= 3 and statuses.count("resume") == 1, why
    i = statuses.index("hold")
    assert np.allclose(actions[i], actions[i - 1], atol=1e-6)  # hold = the previous command
    r = statuses.index("resume")
    assert np.linalg.norm(actions[r][:3] - actions[r - 1][:3]) < 0.01

    # the receivers: nothing malformed, stale or out of order; a fresh sample nearly every step
    for rx in (rt, rg):
        assert rx.stats.malformed == rx.stats.stale == rx.stats.out_of_order == 0
        assert rx.stats.accepted >= 0.9 * len(statuses)

    # haptics arrived at the sending side: one per step, forces on thumb/index, a contact buzz
    h = player.haptics
    assert len(h) >= len(statuses) - 2
    ff = np.array([x.command.force_feedback for x in h])
    vib = np.array([x.command.vibration for x in h])
    assert ff[:, 0].max() > 0.2 and ff[:, 1].max() > 0.2  # left tip -> thumb, right tip -> index
    assert not ff[:, 2:].any() and not vib[:, 2:].any()
    assert vib[:, :2].max() > 0 and max(x.command.vibration_duration_s for x in h) > 0
    assert ff[:20].max() == 0  # no contact before the grasp

    lat = agent.latency_stats()
    assert lat["count"] >= len(statuses) - 10 and lat["p95_s"] < 2.0
    print(f"\nloop {1 / np.mean(step_s):.1f} Hz over {len(step_s)} steps; receipt->haptics latency "
          f"p50 {1e3 * lat['p50_s']:.0f} ms, p95 {1e3 * lat['p95_s']:.0f} ms; {why}")


def test_synthetic_operator_inverts_the_retargeting():
    """Without noise, the synthesized tracker/glove streams make the agent reproduce the gripper
    trajectory they were made from (inverse of eq. 1-2 and of the pinch map + finger FK, eq. 4)."""
    from teleop import HumanTeleopAgent, HumanTeleopConfig, ReplayGlove, ReplayTracker
    from teleop.app.session import SimClock
    from teleop.testing.synth import GripperTrajectory, OperatorModel, PinchPath, distance_for_gap, synthesize_streams
    from teleop.retarget import PinchGapMap, RateLimits
    from teleop.se3 import pose_to_matrix, quat_angle, rotvec_to_quat

    gm = PinchGapMap()
    assert gm.gap(distance_for_gap(gm, 0.03)) == pytest.approx(0.03)
    path = PinchPath()
    lo, hi = path.range_m
    assert lo < gm.d_closed_m and hi > gm.d_open_m  # the pinch path spans the calibrated range
    tips = path.kinematics.fingertip_positions(path.angles_for_distance(0.05))
    assert np.linalg.norm(tips[0] - tips[1]) == pytest.approx(0.05, abs=2e-4)

    dt, n = 0.05, 40
    s = np.linspace(0.0, 1.0, n)
    pos = np.stack([0.1 * s, 0.3 + 0.2 * s, -0.05 * s], axis=1)
    quat = np.array([rotvec_to_quat([0.0, 0.5 * x, 0.2 * x]) for x in s])
    gap = np.clip(0.085 - 0.07 * s, 0.0, 0.085)
    traj = GripperTrajectory(dt, pos, quat, gap, pose_to_matrix(pos[0], quat[0]), 0, {}, None)
    quiet = OperatorModel(drift_m=0, tremor_m=0, rot_jitter_rad=0, rot_drift_rad=0, joint_noise_rad=0, tip_noise_m=0,
                          time_jitter_s=0, drop_fraction=0, dropout_start_s=None, squeeze_m=0, tracker_hz=20, glove_hz=20)
    trackers, gloves = synthesize_streams(traj, quiet, pinch_path=path)
    clock = SimClock()
    fast = RateLimits(max_speed_m_s=100.0, max_angular_speed_rad_s=100.0, max_gap_speed_m_s=100.0, dt=dt)
    agent = HumanTeleopAgent(ReplayTracker(trackers, clock=clock), ReplayGlove(gloves, clock=clock),
                             HumanTeleopConfig(limits=fast, use_ik=False), pinch=None, clock=clock)
    agent.connect()
    obs = {"agent_pos": np.r_[pos[0], quat[0], 0.085, 0.0, 0.0]}
    for k in range(n):
        a = agent.act(obs)
        clock.advance(dt)
        np.testing.assert_allclose(a[:3], pos[k], atol=1e-5)
        assert quat_angle(a[3:7], quat[k]) < 1e-5
        assert a[7] == pytest.approx(max(gap[k], 0.0015112), abs=5e-4)  # the linkage's smallest gap
