"""Teleoperation loop rate and device-to-haptics latency on this machine.

    python benchmarks/bench_teleop.py             # prints the tables, appends them to benchmarks/RESULTS.md
    python benchmarks/bench_teleop.py --no-append --ik analytic --objects cuboid rope --moduli 1e4

Input: the recorded operator stream of ``tests/data`` (recorded on the cuboid, E = 1e5 Pa, seed 0),
sent over loopback UDP to the real receivers.

Table 1 (per-component times): the stream's own object (cuboid, E = 1e5), both wrist IK back-ends.
Table 2 (every object x E, analytic IK, the app's default): the same operator stream driving each
of the five objects at E = 1e4 and 1e7 Pa (the gripper closes where the cuboid was: ``held`` counts
the steps with both tip forces > 0.5 N, so a row says whether it measured a grasp). Loop rates are
p50 and p95 (the rate that 95 % of the steps reach, 1 / the 95th percentile of the step time),
unpaced and paced at the control rate (then from the step start times: a step that overran the
period delays the next), and the latency as in 2. below. Target: paced p95 >= 20 Hz.

1. Loop rate (lock-step replay, unpaced): per control step, the time of the device reads
   (tracker + glove receivers), retargeting (eq. 1-2 offset + rate limits, and the eq. 4 pinch with
   finger FK), the wrist IK (eq. 3), ``env.step`` and the haptic feedback; loop rate = 1 / mean
   total. Both wrist IK back-ends: ``analytic`` (the app's default) and ``iterative``
   (pytorch-kinematics, the agent's default).
2. Latency (real time): a bridge process streams the recording on the wall clock (60 Hz tracker,
   50 Hz glove, looped) while the loop runs paced at the control rate, as in ``defgrasp-teleop``.
   * agent: receipt of the newest sample by the receiver (its read) -> haptic command sent
     (``HumanTeleopAgent.latency_stats``);
   * bridge: the sample leaving the bridge (``sendto``) -> the haptic command computed from it
     arriving back at the bridge: adds the wait in the socket until the loop reads it (0..1
     control period) and the UDP hops. The older of the two samples (tracker, glove) counts.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import pathlib
import platform
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))

import numpy as np  # noqa: E402
from machine import append_results, git_state, host  # noqa: E402

DATA = ROOT / "tests" / "data"
STREAM = "human_pick_cuboid"


# timing proxies (the agent only sees PoseTracker / HapticGlove / solve / __call__) -----------------
def timed_devices(tracker, glove, log: dict):
    from teleop.sensors.base import HapticGlove, PoseTracker

    class TimedTracker(PoseTracker):
        def connect(self):
            tracker.connect()

        def disconnect(self):
            tracker.disconnect()

        @property
        def is_connected(self):
            return tracker.is_connected

        def read(self):
            t = time.perf_counter()
            s = tracker.read()
            log["read"] += time.perf_counter() - t
            return s

    class TimedGlove(HapticGlove):
        def connect(self):
            glove.connect()

        def disconnect(self):
            glove.disconnect()

        @property
        def is_connected(self):
            return glove.is_connected

        def read(self):
            t = time.perf_counter()
            s = glove.read()
            log["read"] += time.perf_counter() - t
            return s

        def send_haptics(self, *a):
            return glove.send_haptics(*a)

    return TimedTracker(), TimedGlove()


class Timed:
    """Proxy timing ``solve`` / ``__call__`` of the wrapped object into ``log[key]``."""

    def __init__(self, inner, log: dict, key: str):
        self._inner, self._log, self._key = inner, log, key

    def solve(self, *a, **kw):
        t = time.perf_counter()
        r = self._inner.solve(*a, **kw)
        self._log[self._key] += time.perf_counter() - t
        return r

    def __call__(self, *a, **kw):
        t = time.perf_counter()
        r = self._inner(*a, **kw)
        self._log[self._key] += time.perf_counter() - t
        return r

    def __getattr__(self, name):
        return getattr(self._inner, name)


def make_setup(ik: str, env_overrides: dict | None = None):
    import gymnasium as gym

    import defgrasp_env  # noqa: F401
    from teleop import HumanTeleopAgent, HumanTeleopConfig, UdpGloveReceiver, UdpTrackerReceiver
    from teleop.app.cli import one_torch_thread
    from teleop.app.devices import IK_SOLVERS
    from teleop.retarget import PinchRetargeter, RateLimits

    one_torch_thread()  # as defgrasp-teleop does

    meta = json.loads((DATA / f"{STREAM}.json").read_text())
    env = gym.make("DeformablePickup-v0", action_mode="absolute", **{**meta["env_kwargs"], **(env_overrides or {})})
    dt = env.unwrapped.config.dt
    rt, rg = UdpTrackerReceiver("127.0.0.1", 0), UdpGloveReceiver("127.0.0.1", 0)
    log = {"read": 0.0, "ik": 0.0, "pinch": 0.0}
    tt, tg = timed_devices(rt, rg, log)
    agent = HumanTeleopAgent(tt, tg, HumanTeleopConfig(limits=RateLimits(dt=dt)),
                             wrist_ik=Timed(IK_SOLVERS[ik](), log, "ik"), pinch=Timed(PinchRetargeter(), log, "pinch"))
    agent.connect()
    return meta, env, dt, rt, rg, agent, log


def bench_loop(ik: str, env_overrides: dict | None = None) -> dict:
    """Part 1: lock-step replay, unpaced; per-step component times."""
    from teleop.testing.udp_replay import StreamPlayer

    meta, env, dt, rt, rg, agent, log = make_setup(ik, env_overrides)
    player = StreamPlayer(DATA / f"{STREAM}_tracker.jsonl", DATA / f"{STREAM}_glove.jsonl",
                          tracker_address=rt.address, glove_address=rg.address)
    rows = []
    obs, _ = env.reset(seed=meta["seed"])
    agent.reset()
    info = {}
    held = 0
    try:
        for k in range(env.spec.max_episode_steps):
            player.advance_to(k * dt)
            for key in log:
                log[key] = 0.0
            t0 = time.perf_counter()
            action = agent.act(obs)
            t1 = time.perf_counter()
            obs, _, term, trunc, info = env.step(action)
            t2 = time.perf_counter()
            agent.send_feedback(info)
            t3 = time.perf_counter()
            rows.append((log["read"], t1 - t0 - log["read"] - log["ik"] - log["pinch"], log["pinch"], log["ik"],
                         t2 - t1, t3 - t2, t3 - t0))
            player.poll_haptics()
            held += min(info["left_tip_normal_force"], info["right_tip_normal_force"]) > 0.5
            if term or trunc:
                break
    finally:
        player.close()
        agent.disconnect()
        env.close()
    a = np.array(rows[3:])  # skip warm-up steps
    names = ("read", "retarget", "pinch_fk", "ik", "env_step", "feedback", "total")
    mean = dict(zip(names, a.mean(axis=0)))
    return {"ik": ik, "steps": len(rows), "success": bool(info.get("is_success", False)), "mean_s": mean,
            "p95_total_s": float(np.percentile(a[:, -1], 95)), "loop_hz": 1.0 / mean["total"],
            "p50_hz": 1.0 / float(np.median(a[:, -1])), "p95_hz": 1.0 / float(np.percentile(a[:, -1], 95)),
            "held": held}


def _bridge(tracker_address, glove_address, stop, results) -> None:
    """The glove/tracker bridge, in its own process (as on a real setup): streams the recording in
    real time, in a loop, and reports what it sent and the haptics it got back (host monotonic
    clock, shared by all processes on Linux)."""
    sys.path.insert(0, str(ROOT))
    from teleop.testing.udp_replay import StreamPlayer, run_realtime

    player = StreamPlayer(DATA / f"{STREAM}_tracker.jsonl", DATA / f"{STREAM}_glove.jsonl",
                          tracker_address=tracker_address, glove_address=glove_address)
    try:
        run_realtime(player, loop=True, period_s=0.0005, should_stop=stop.is_set)
    finally:
        player.close()
        results.put((list(player.sent_log), [(h.command.t_sender_s, h.t_received_s) for h in player.haptics]))


def bench_latency(ik: str, seconds: float, env_overrides: dict | None = None) -> dict:
    """Part 2: real-time bridge process + loop paced at the control rate."""
    import multiprocessing as mp

    meta, env, dt, rt, rg, agent, log = make_setup(ik, env_overrides)
    ctx = mp.get_context("spawn")
    stop, results = ctx.Event(), ctx.Queue()
    bridge = ctx.Process(target=_bridge, args=(rt.address, rg.address, stop, results), daemon=True)
    obs, _ = env.reset(seed=meta["seed"])
    agent.reset()
    steps = []  # (t_act_start, t_feedback_done, tracker seq, glove seq)
    bridge.start()
    t_wait = time.monotonic() + 30.0
    while (rt.stats.accepted == 0 or rg.stats.accepted == 0) and time.monotonic() < t_wait:
        rt.read(), rg.read()  # wait for the bridge process to stream
        time.sleep(0.01)
    t_next = time.monotonic()
    t_end = t_next + seconds
    try:
        while time.monotonic() < t_end:
            t0 = time.monotonic()
            action = agent.act(obs)
            seqs = (rt.stats.last_sequence, rg.stats.last_sequence)
            obs, _, term, trunc, info = env.step(action)
            agent.send_feedback(info)
            steps.append((t0, time.monotonic(), *seqs))
            if term or trunc:
                obs, _ = env.reset(seed=meta["seed"])
                agent.reset()
            t_next += dt
            time.sleep(max(0.0, t_next - time.monotonic()))
        time.sleep(0.05)
    finally:
        stop.set()
        sent_log, haptics = results.get(timeout=30.0)
        bridge.join(timeout=5.0)
        agent.disconnect()
        env.close()
    sent = {(kind, seq): t for kind, seq, t in sent_log}
    hap = sorted(haptics)
    h_sent = np.array([x[0] for x in hap])
    bridge_lat = []
    for t0, t1, seq_t, seq_g in steps[3:]:
        i = np.searchsorted(h_sent, t0)
        if i >= len(hap) or hap[i][0] > t1 or (("tracker", seq_t) not in sent) or (("glove", seq_g) not in sent):
            continue  # lost (a bridge poll can only see the newest) or a sample from the previous loop of the stream
        bridge_lat.append(hap[i][1] - min(sent[("tracker", seq_t)], sent[("glove", seq_g)]))
    agent_lat = np.array(list(agent.latencies)[3:])
    achieved = (len(steps) - 1) / (steps[-1][0] - steps[0][0])
    periods = np.diff([s[0] for s in steps[3:]])
    return {"ik": ik, "steps": len(steps), "paced_hz": achieved,
            "paced_p50_hz": 1.0 / float(np.median(periods)), "paced_p95_hz": 1.0 / float(np.percentile(periods, 95)),
            "late_share": float(np.mean(periods > 1.5 * dt)),
            "agent_p50_s": float(np.median(agent_lat)), "agent_p95_s": float(np.percentile(agent_lat, 95)),
            "bridge_p50_s": float(np.median(bridge_lat)), "bridge_p95_s": float(np.percentile(bridge_lat, 95)),
            "bridge_n": len(bridge_lat)}


def table(loops: list[dict], lats: list[dict]) -> str:
    ms = lambda s: f"{1e3 * s:.1f}"  # noqa: E731
    head = "| | " + " | ".join(f"{r['ik']} IK" for r in loops) + " |"
    sep = "|---|" + "---|" * len(loops)
    lines = [head, sep]

    def row(label, fn):
        lines.append(f"| {label} | " + " | ".join(fn(r) for r in loops) + " |")

    row("loop rate, unpaced (Hz)", lambda r: f"**{r['loop_hz']:.1f}**")
    row("step total mean / p95 (ms)", lambda r: f"{ms(r['mean_s']['total'])} / {ms(r['p95_total_s'])}")
    for key, label in (("read", "device read (UDP tracker + glove)"), ("retarget", "retarget: offset eq. 1-2 + rate limits"),
                       ("pinch_fk", "retarget: pinch + finger FK eq. 4"), ("ik", "wrist IK eq. 3"),
                       ("env_step", "env.step"), ("feedback", "haptic feedback")):
        row(f"{label} (ms, share)", lambda r, k=key: f"{ms(r['mean_s'][k])} ({100 * r['mean_s'][k] / r['mean_s']['total']:.0f} %)")
    row("episode (steps, success)", lambda r: f"{r['steps']}, {r['success']}")
    by_ik = {r["ik"]: r for r in lats}
    if lats:
        row("paced at 20 Hz: achieved (Hz)", lambda r: f"{by_ik[r['ik']]['paced_hz']:.1f}" if r["ik"] in by_ik else "-")
        row("latency receipt -> haptics p50 / p95 (ms)",
            lambda r: f"{ms(by_ik[r['ik']]['agent_p50_s'])} / {ms(by_ik[r['ik']]['agent_p95_s'])}" if r["ik"] in by_ik else "-")
        row("latency sample sent -> haptics at bridge p50 / p95 (ms)",
            lambda r: f"{ms(by_ik[r['ik']]['bridge_p50_s'])} / {ms(by_ik[r['ik']]['bridge_p95_s'])}" if r["ik"] in by_ik else "-")
    return "\n".join(lines)


def sweep_table(rows: list[tuple[str, float, dict, dict]]) -> str:
    ms = lambda s: f"{1e3 * s:.0f}"  # noqa: E731
    lines = ["| object | E (Pa) | steps (held) | unpaced p50 / p95 (Hz) | env.step mean (ms) | paced p50 / p95 (Hz) "
             "| periods > 1.5 dt | latency receipt -> haptics p50 / p95 (ms) | p95 >= 20 Hz |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, e, loop, lat in rows:
        lines.append(f"| {name} | {e:.0e} | {loop['steps']} ({loop['held']}) | {loop['p50_hz']:.1f} / {loop['p95_hz']:.1f} "
                     f"| {ms(loop['mean_s']['env_step'])} | {lat['paced_p50_hz']:.1f} / {lat['paced_p95_hz']:.1f} "
                     f"| {100 * lat['late_share']:.0f} % | {ms(lat['agent_p50_s'])} / {ms(lat['agent_p95_s'])} "
                     f"| {'yes' if lat['paced_p95_hz'] >= 19.5 else '**no**'} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--ik", choices=("both", "analytic", "iterative"), default="both")
    p.add_argument("--latency-seconds", type=float, default=8.0, help="length of each real-time run (s)")
    p.add_argument("--no-append", action="store_true", help="do not append to the results file")
    p.add_argument("--results", default=str(ROOT / "benchmarks" / "RESULTS.md"), help="results file to append to")
    p.add_argument("--note", default="", help="free text added to the machine line (e.g. the code version)")
    p.add_argument("--objects", nargs="*", default=None, help="objects of table 2 (default: all five; none: skip it)")
    p.add_argument("--moduli", nargs="*", type=float, default=[1e4, 1e7], help="E values of table 2 (Pa)")
    p.add_argument("--no-components", action="store_true", help="skip table 1")
    p.add_argument("--device", default="cpu", help="Warp device of the simulation (cpu, cuda:0), as defgrasp-teleop "
                                                   "--env-device")
    args = p.parse_args(argv)
    iks = ("analytic", "iterative") if args.ik == "both" else (args.ik,)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    from defgrasp_env.sim.meshing import OBJECT_SHAPES

    objects = list(OBJECT_SHAPES) if args.objects is None else args.objects
    sweep = []
    for name in objects:
        for e in args.moduli:
            kw = {"object": name, "youngs_modulus": e, "device": args.device}
            sweep.append((name, e, bench_loop("analytic", kw), bench_latency("analytic", args.latency_seconds, kw)))
            print(sweep_table(sweep[-1:]).splitlines()[-1], flush=True)
    on_device = {"device": args.device}
    loops = [] if args.no_components else [bench_loop(ik, on_device) for ik in iks]
    lats = [] if args.no_components else [bench_latency(ik, args.latency_seconds, on_device) for ik in iks]
    machine = (f"{host()}, "
               f"load average {load:.1f} at start; Python {platform.python_version()}; env on Warp {args.device}; commit {git_state()}"
               + (f"; {args.note}" if args.note else ""))
    out = (f"\n## Teleop loop (bench_teleop.py), {datetime.datetime.now().isoformat(timespec='seconds')}\n\n"
           f"Machine: {machine}.\nStream: tests/data/{STREAM}_*.jsonl over loopback UDP.\n")
    if sweep:
        missed = [f"{n} {e:.0e}" for n, e, _, lat in sweep if lat["paced_p95_hz"] < 19.5]
        out += (f"\nEvery object x E, analytic wrist IK, paced at the control rate (20 Hz); target paced p95 >= 20 Hz: "
                + ("met by every row" if not missed else f"NOT met by {', '.join(missed)}")
                + f"\n\n{sweep_table(sweep)}\n")
    if loops:
        best = max(loops, key=lambda r: r["loop_hz"])
        verdict = "met" if best["loop_hz"] >= 30 else (
            f"NOT met: env.step alone takes {1e3 * best['mean_s']['env_step']:.0f} ms "
            f"({100 * best['mean_s']['env_step'] / best['mean_s']['total']:.0f} % of the step); the teleop part "
            f"(read + retarget + IK + feedback) takes {1e3 * (best['mean_s']['total'] - best['mean_s']['env_step']):.1f} ms "
            f"with {best['ik']} IK")
        out += (f"\nComponents, the stream's own object (cuboid, E = 1e5 Pa). Target >= 30 Hz loop: {verdict}.\n"
                f"(shares are of the mean step; other processes on the machine add noise)\n\n{table(loops, lats)}\n")
    print(out)
    if not args.no_append:
        append_results(out, args.results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
