"""``defgrasp-teleop``: record demonstrations of DeformablePickup-v0 by teleoperation.

    defgrasp-teleop --tracker udp --glove udp --object torus --youngs-modulus 1e4
    defgrasp-teleop --tracker openvr --glove udp --episodes 20 --out datasets/output/teleop
    defgrasp-teleop --tracker keyboard                      # no hardware: keys move the gripper
    defgrasp-teleop --spacemouse
    defgrasp-teleop --tracker replay:tests/data/human_pick_cuboid_tracker.jsonl \\
                    --glove replay:tests/data/human_pick_cuboid_glove.jsonl --seed 0 --fixed-seed

Keys (as LeRobot's record): right arrow = end the episode and keep it, left arrow = discard it and
record it again, s = mark it a success (toggle), Esc = stop (the current episode is kept). Ctrl-C
stops too, discarding the unfinished episode unless --keep-interrupted. Each episode waits for
device data (enter/space starts it anyway; --no-wait starts at once). The live view is at
http://127.0.0.1:8765/ unless --no-view: a 3D view in the browser (--view 3d, the default: the
object deforming, coloured by stress, pads, wrist, goal, tip-force arrows, episode status; needs
the [viewer] extra) or the camera image with a readout table (--view 2d); --view-png also keeps a
PNG file refreshed. Over SSH: ssh -L 8765:127.0.0.1:8765 HOST, then open http://127.0.0.1:8765/. Episodes go to --out as HDF5 files (one per episode, written
atomically by defgrasp_env.recording.HDF5Recorder); check them with ``defgrasp-dataset validate``.
"""

from __future__ import annotations

import argparse
import importlib.util
import logging
import os
import pathlib
import sys

DEFAULT_OUT = "datasets/output/teleop"
DEFAULT_VIEW_PORT = 8765


def _default_caches() -> None:
    try:
        from defgrasp_env.recording.cli import default_caches
    except ImportError:
        os.environ.setdefault("WARP_CACHE_PATH", str(pathlib.Path.cwd() / ".cache" / "warp"))
        return
    default_caches()


def one_torch_thread() -> None:
    """Run torch on one thread in this process. The app's torch work (finger FK, iterative wrist
    IK) is a few 4x4 products per step; torch's extra OpenMP threads keep spinning after each call
    and take the core the simulation runs on (measured with the iterative IK on this 2-core box:
    env.step 28 -> 22 ms, loop 25.5 -> 31.7 Hz)."""
    import torch

    torch.set_num_threads(1)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="defgrasp-teleop", description=__doc__.split("\n\n")[0],
                                epilog=__doc__.split("\n\n", 1)[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    d = p.add_argument_group("devices")
    d.add_argument("--tracker", default=None, help="udp | openvr[:SERIAL] | replay:PATH | keyboard (default udp)")
    d.add_argument("--glove", default=None, help="udp | replay:PATH | none (default: udp with a pose tracker, "
                   "none with keyboard/SpaceMouse; none + a pose tracker: q/e open/close the jaw)")
    d.add_argument("--spacemouse", action="store_true", help="drive the gripper with a 3Dconnexion SpaceMouse")
    d.add_argument("--keys", default="auto", help="key source: auto | pynput | terminal | none (default auto)")
    d.add_argument("--udp-host", default="127.0.0.1", help="address the UDP receivers bind (0.0.0.0: any)")
    d.add_argument("--tracker-port", type=int, default=None, help="UDP tracker port (default 47002)")
    d.add_argument("--glove-port", type=int, default=None, help="UDP glove port (default 47001)")
    d.add_argument("--ik", default="analytic", choices=("analytic", "iterative"), help="wrist IK (eq. 3)")
    d.add_argument("--calibration", default="full", choices=("full", "align_axes"), help="offset calibration mode (eq. 1-2)")
    t = p.add_argument_group("task")
    t.add_argument("--object", default="cuboid", help="cuboid | torus | cylinder | sphere | rope | random | PATH")
    t.add_argument("--youngs-modulus", type=float, default=1e5, help="Young's modulus E in Pa (default 1e5)")
    t.add_argument("--env-device", default="cpu", help="Warp device of the simulation (cpu, cuda:0)")
    r = p.add_argument_group("recording")
    r.add_argument("--episodes", type=int, default=10, help="episodes to keep (default 10)")
    r.add_argument("--out", default=DEFAULT_OUT, help=f"episode folder (default {DEFAULT_OUT})")
    r.add_argument("--no-record", action="store_true", help="do not write episodes")
    r.add_argument("--reset-time-s", type=float, default=2.0, help="review time between episodes (default 2 s)")
    r.add_argument("--seed", type=int, default=None, help="reset seed of the first episode (+1 per attempt)")
    r.add_argument("--fixed-seed", action="store_true", help="use --seed for every episode")
    r.add_argument("--keep-interrupted", action="store_true", help="on Ctrl-C keep the unfinished episode")
    r.add_argument("--no-realtime", action="store_true", help="do not pace the loop at the control rate")
    r.add_argument("--no-wait", action="store_true", help="start each episode at once, not when device data arrives")
    v = p.add_argument_group("live view")
    v.add_argument("--no-view", action="store_true", help="no HTTP live view")
    v.add_argument("--view", default="3d", choices=("3d", "2d"), help="3d: browser 3D viewer (default); 2d: camera image page")
    v.add_argument("--view-host", default="127.0.0.1")
    v.add_argument("--view-port", type=int, default=DEFAULT_VIEW_PORT, help=f"HTTP port (default {DEFAULT_VIEW_PORT}; 0: any free)")
    v.add_argument("--view-png", default=None, help="also keep this PNG file refreshed with the scene")
    v.add_argument("--view-hz", type=float, default=None,
                   help="live view refresh rate (default: the control rate for 3d, 5 Hz for 2d)")
    return p


def check_object(name: str) -> None:
    """``--object``: a named shape, ``random`` or an existing surface-mesh file; ValueError listing the names."""
    from defgrasp_env.sim.meshing import OBJECT_SHAPES

    if name in OBJECT_SHAPES or name == "random" or pathlib.Path(name).is_file():
        return
    raise ValueError(f"--object must be one of {sorted(OBJECT_SHAPES) + ['random']} or a surface-mesh file, "
                     f"got {name!r} (no such object or file)")


def run(args: argparse.Namespace, *, say=None):
    """Build everything from parsed arguments and run the session; returns its report."""
    from .devices import DeviceContext, build_controller
    from .keys import make_key_source
    from .session import CollectionSession, SessionConfig, SimClock, make_env_stack
    from .view import LiveView, SceneView3D
    from ..agent import HumanTeleopConfig
    from ..sensors.udp_glove import DEFAULT_GLOVE_PORT
    from ..sensors.udp_tracker import DEFAULT_TRACKER_PORT
    from ..retarget.smoothing import RateLimits

    tell = say or print
    check_object(args.object)
    view_3d = not args.no_view and args.view == "3d"
    if view_3d and importlib.util.find_spec("viser") is None:
        tell("WARNING: the 3D view needs the [viewer] extra (pip install 'defgrasp[viewer]'); serving the 2D page")
        args.view, view_3d = "2d", False
    view_hz = args.view_hz if args.view_hz is not None else (20.0 if view_3d else 5.0)
    config = SessionConfig(num_episodes=args.episodes, reset_time_s=args.reset_time_s, realtime=not args.no_realtime,
                           view_hz=view_hz, seed=args.seed, fixed_seed=args.fixed_seed,
                           keep_interrupted=args.keep_interrupted, wait_for_devices=not args.no_wait)
    views = []
    if view_3d:
        views.append(SceneView3D(args.view_host, args.view_port, "--view-port"))  # port checked before the env is built
        tell(f"live view: {views[-1].url}")
    keys = make_key_source(args.keys)
    if args.tracker == "keyboard" and keys.name == "none":
        tell("WARNING: --tracker keyboard without a key source: the gripper will not move")
    render = (not args.no_view and args.view == "2d") or args.view_png is not None
    try:
        env, recorder, marks = make_env_stack({"object": args.object, "youngs_modulus": args.youngs_modulus,
                                               "device": args.env_device},
                                              out_dir=None if args.no_record else args.out, render=render, say=tell)
    except BaseException:
        for v in views:
            v.close()
        raise
    sim_clock = SimClock()
    dt = float(env.unwrapped.config.dt)
    try:
        ctx = DeviceContext(held_keys=keys.held, episode_clock=sim_clock, host=args.udp_host,
                            tracker_port=args.tracker_port or DEFAULT_TRACKER_PORT,
                            glove_port=args.glove_port or DEFAULT_GLOVE_PORT, dt=dt)
        agent_cfg = HumanTeleopConfig(limits=RateLimits(dt=dt), calibration_mode=args.calibration)
        controller = build_controller(args.tracker, args.glove, spacemouse=args.spacemouse, ctx=ctx,
                                      agent_config=agent_cfg, ik=args.ik)
        if render:
            views.append(LiveView(args.view_png, None if (args.no_view or view_3d) else (args.view_host, args.view_port)))
            if views[-1].url:
                tell(f"live view: {views[-1].url}")
    except BaseException:
        env.close()
        for v in views:
            v.close()
        raise
    session = CollectionSession(env, controller, keys, recorder=recorder, marks=marks, view=views, config=config,
                                sim_clock=sim_clock, say=say)
    return session.run()


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    _default_caches()
    one_torch_thread()
    try:
        report = run(args)
    except (ValueError, TypeError, ImportError, OSError, RuntimeError) as exc:
        print(f"defgrasp-teleop: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\ndefgrasp-teleop: aborted", file=sys.stderr)
        return 130
    for p in report.saved:
        print(f"  {p}")
    if report.loop_rate_hz:
        print(f"loop rate p50 {report.loop_rate_hz['p50']:.1f} Hz, p95 {report.loop_rate_hz['p95']:.1f} Hz; "
              f"{report.late_steps} step(s) more than a control period late")
    if report.loop_hz:
        print(f"loop {report.loop_hz:.1f} Hz (step p50 {1e3 * report.step_time_s['p50']:.0f} ms, "
              f"p95 {1e3 * report.step_time_s['p95']:.0f} ms)"
              + (f"; device->haptics latency p50 {1e3 * report.latency['p50_s']:.0f} ms" if report.latency.get("count") else ""))
    return 0 if report.stopped_by != "error" else 1


if __name__ == "__main__":
    raise SystemExit(main())
