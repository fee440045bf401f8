"""Evaluate a saved PPO run (``train_ppo.py``'s folder) on fresh episodes: one episode per world.

The success rates ``train_ppo.py`` prints per rollout are those of the stochastic training policy,
of the episodes that ended in the rollout (which swings when worlds begin their episodes together:
successes end early, failures at the time limit) and of a cohort of earlier-begun episodes. This
script gives the policy's success rate as a user sees it: N worlds
each run one episode from its reset to its end (success or the time limit), actions from the
policy's mean (``--stochastic`` samples them instead), observation normalisation frozen. Env
options are the run's (``run.json``) unless given (``--object``, ``--youngs-modulus``: a policy
evaluated on another object or stiffness than it was trained on; ``--edge-contact`` /
``--no-edge-contact``: with or without the pads' box edges held out of the object,
``PickupConfig.edge_contact``; a run.json without the key is a run trained without it, before it
became the default). Seeds start at ``--seed`` (default
10**9: none of the training episodes' seeds, which count from the run's seed by env steps).

A run trained on several objects with ``--fixed-world-objects`` is evaluated so (world i holds
the i-th object) and reported per object too, unless ``--object`` overrides the objects (then
drawn per episode from those given). Per episode it records the object, success, the step of
success, and how far the policy got, so a failure is named: ``never grasped``, ``grasped, never
at the goal`` (grasped but never within the success tolerance of the goal, pierced steps not
counted), ``at the goal, not held`` (within it while
grasped, not for the hold time). Heights of an episode's last step come from the terminal
observation VecNormalize returns, unnormalised (exact unless a value was clipped at 10 std).
``--workers N`` spreads the worlds over N processes (one CPU core each on the CPU) with the same
episodes as one process.

    python benchmarks/eval_ppo.py datasets/output/ppo_place --worlds 32 --device cpu --workers 2
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import multiprocessing
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402

from defgrasp_env.layout import AGENT_POS, ENV_STATE  # noqa: E402
from defgrasp_env.rl.ppo_policy import run_env_options  # noqa: E402
from machine import numeric_host  # noqa: E402
from train_ppo import load_normalisation, make_vec_env, parse_object  # noqa: E402

OUTCOMES = ("success", "at the goal, not held", "grasped, never at the goal", "never grasped")


def feature_beyond_pad_faces(scene) -> np.ndarray:
    """[W, 2] m: ``envs.task.feature_beyond_pad_faces`` of the scene's current state (its solver's
    pad poses)."""
    from defgrasp_env.envs.task import feature_beyond_pad_faces as beyond

    pads = scene.model.pads_per_world
    pos = scene.state.pad_positions.numpy().reshape(scene.num_worlds, pads, 3)
    quat = scene.state.pad_orientations.numpy().reshape(scene.num_worlds, pads, 4)
    return beyond(scene.feature_points()[0], pos, quat)


def run_settings(run: pathlib.Path, env_overrides: dict) -> tuple[dict, dict, bool]:
    """The run's settings (``run.json``), the env options to evaluate with (the run's, read as
    recorded files are, then ``env_overrides``: keys of ``rl.ppo_policy.RUN_ENV_OPTIONS``, None = the
    run's; ``rl.ppo_policy.run_env_options``) and
    whether world i holds the run's i-th object (``--fixed-world-objects`` runs, unless the object
    is overridden)."""
    settings = json.loads((pathlib.Path(run) / "run.json").read_text())
    # a run.json lacks options left at their default, and edge_contact where it was off (every run
    # before it became the default on 2026-11-26): read as recorded files are
    options = run_env_options(settings, **env_overrides)
    fixed = bool(settings.get("fixed_world_objects", False)) and env_overrides.get("object") is None
    return settings, options, fixed


def evaluate(run: pathlib.Path, num_worlds: int, seed: int = 10**9, device: str = "cpu",
             torch_device: str = "cpu", deterministic: bool = True, workers: int = 1, **env_overrides) -> dict:
    """Run ``num_worlds`` episodes (one per world) of the run's policy; returns the settings, the
    per-episode records (``success``, ``steps``, ``success_step``, ``outcome``, ``min_goal_distance``
    while grasped (m), ``grasped_steps``, ``max_lift`` of the feature point above its start (m),
    ``final_flange_height`` (m, world y), ``max_wrist_force`` (N), ``least_grasped_gap`` and
    ``final_gap`` of the jaw (m), ``pierced_steps``, ``penetrated_steps`` (steps flagged
    ``sim_penetrated``: a node deeper than the solver's bound), ``max_penetration`` (m, of
    ``info["penetration"]``), ``hold_beyond_pad_faces`` [length, width] (m,
    ``feature_beyond_pad_faces`` at the last grasped step; None if never grasped),
    ``median_grasp_quality`` (of ``info["grasp_quality"]`` over the grasped steps; None if never
    grasped), ``pressed_steps`` (steps whose force term charged: a wrist force above
    ``envs.task.FORCE_FREE``), ``newton_iterations_median`` and ``_max`` (``info["newton_iterations"]``
    per step: what a batched step waits for is its slowest world's), ``return``) and
    their summary (``success_rate``, outcome counts), and ``host`` (``machine.numeric_host``: where
    the same code repeats these episodes bit for bit).

    ``workers`` > 1 splits the worlds into that many consecutive blocks, each evaluated in its own
    process (seeds and, for a fixed-world-objects run, objects as in one process: a block starts
    at a multiple of the object count), with the same episodes as one process gives (a world's
    episode depends on its seed only)."""
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an int >= 1, got {workers!r}")
    run = pathlib.Path(run)
    settings, env_options, fixed = run_settings(run, env_overrides)
    if workers == 1:
        records, wall = _episodes(run, num_worlds, seed, device, torch_device, deterministic, settings,
                                  env_options, fixed)
    else:
        from defgrasp_env import PickupConfig

        period = len(PickupConfig(**env_options).object_names) if fixed else 1  # world i: object i mod period
        per_worker = -(-num_worlds // workers)
        size = -(-per_worker // period) * period  # worlds per block: a multiple of the period
        with concurrent.futures.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            blocks = [pool.submit(_episodes, run, min(size, num_worlds - start), seed + start, device, torch_device,
                                  deterministic, settings, env_options, fixed) for start in range(0, num_worlds, size)]
            records = [r for block in blocks for r in block.result()[0]]
            wall = max(block.result()[1] for block in blocks)  # the episodes' time, as in one process
    counts = {o: sum(r["outcome"] == o for r in records) for o in OUTCOMES}
    success_steps = [r["success_step"] for r in records if r["success"]]
    objects = [r["object"] for r in records]
    by_object = {name: {o: sum(r["outcome"] == o for r in records if r["object"] == name) for o in OUTCOMES}
                 for name in dict.fromkeys(objects)}
    return {"run": str(run), "host": numeric_host(), "worlds": num_worlds, "seed": seed, "device": device,
            "deterministic": deterministic,
            "workers": workers, "env": env_options, "fixed_world_objects": fixed,
            "success_rate": counts["success"] / num_worlds, "outcomes": counts, "outcomes_by_object": by_object,
            "success_step_median": float(np.median(success_steps)) if success_steps else None,
            "wall_s": round(wall, 1), "episodes": records}


def _episodes(run, num_worlds: int, seed: int, device: str, torch_device: str, deterministic: bool,
              settings: dict, env_options: dict, fixed: bool) -> tuple[list[dict], float]:
    """The episode records of worlds 0..num_worlds-1 (seeds from ``seed``) and the wall time (s)."""
    from stable_baselines3 import PPO

    from defgrasp_env import PickupConfig

    run = pathlib.Path(run)
    config = PickupConfig(**env_options)
    venv = make_vec_env(num_worlds, seed, actions=settings["actions"], gamma=settings["gamma"], device=device,
                        fixed_world_objects=fixed, **env_options)
    venv = load_normalisation(run, venv)
    venv.training, venv.norm_reward = False, False
    model = PPO.load(run / "ppo.zip", device=torch_device)
    tolerance = config.success_tolerance  # m
    obs = venv.reset()
    objects = venv.unwrapped.env.unwrapped.scene.object_names  # each world's object in its episode
    closest = np.full(num_worlds, np.inf)  # m, the feature point's least goal distance while grasped
    grasped_ever = np.zeros(num_worlds, bool)
    grasped_steps = np.zeros(num_worlds, int)
    start_height = ENV_STATE.get(venv.get_original_obs()["environment_state"], "feature_position")[:, 1].copy()
    lift = np.zeros(num_worlds)  # m, the feature point's greatest rise above its start
    wrist_force = np.zeros(num_worlds)  # N, the greatest wrist force
    least_gap = np.full(num_worlds, np.inf)  # m, the jaw's least gap while grasped
    pierced_steps = np.zeros(num_worlds, int)  # steps whose info["pierced"] was set
    penetrated_steps = np.zeros(num_worlds, int)  # steps whose info["sim_penetrated"] was set
    penetration = np.zeros(num_worlds)  # m, the greatest info["penetration"]
    hold_beyond = np.full((num_worlds, 2), np.nan)  # m, feature_beyond_pad_faces at the last grasped step
    qualities: list[list[float]] = [[] for _ in range(num_worlds)]  # info["grasp_quality"] of grasped steps
    pressed_steps = np.zeros(num_worlds, int)  # steps whose info["reward_force"] < 0
    newton: list[list[int]] = [[] for _ in range(num_worlds)]  # info["newton_iterations"] per step
    scene = venv.unwrapped.env.unwrapped.scene
    records: list[dict | None] = [None] * num_worlds
    t0 = time.perf_counter()
    while any(r is None for r in records):
        # one world at a time: a batched forward pass rounds differently with the batch size
        # (~1e-7), which the contact dynamics amplify into another episode; so a seed's episode
        # does not depend on --worlds
        actions = np.concatenate([model.predict({k: v[i:i + 1] for k, v in obs.items()},
                                                deterministic=deterministic)[0] for i in range(num_worlds)])
        obs, _, dones, infos = venv.step(actions)
        raw = venv.get_original_obs()
        # the scene holds the step's state for worlds that did not end (an ended world is reset:
        # its last hold geometry is that of the step before, the same hold)
        beyond = feature_beyond_pad_faces(scene)
        for i, (done, info) in enumerate(zip(dones, infos)):
            if records[i] is not None:
                continue
            grasped = bool(info.get("grasped", False))
            grasped_ever[i] |= grasped
            grasped_steps[i] += grasped
            pierced_steps[i] += bool(info.get("pierced", False))
            penetrated_steps[i] += bool(info["sim_penetrated"])
            penetration[i] = max(penetration[i], float(info["penetration"]))
            pressed_steps[i] += float(info["reward_force"]) < 0.0
            newton[i].append(int(info["newton_iterations"]))
            if grasped and not done:
                hold_beyond[i] = beyond[i]
            if grasped:
                qualities[i].append(float(info["grasp_quality"]))
            if grasped and not info.get("pierced", False):  # a pierced hold is not "at the goal"
                closest[i] = min(closest[i], float(info["goal_distance"]))
                least_gap[i] = min(least_gap[i], float(info["jaw_gap"]))
            last = venv.unnormalize_obs(info["terminal_observation"]) if done else {k: v[i] for k, v in raw.items()}
            flange = AGENT_POS.get(last["agent_pos"], "wrist_position")
            lift[i] = max(lift[i], float(ENV_STATE.get(last["environment_state"], "feature_position")[1]) - start_height[i])
            wrist_force[i] = max(wrist_force[i], float(info["wrist_force"]))
            if done:
                success = bool(info.get("is_success", False))
                steps = int(info["episode"]["l"])
                outcome = ("success" if success else "at the goal, not held" if closest[i] < tolerance
                           else "grasped, never at the goal" if grasped_ever[i] else "never grasped")
                records[i] = {"seed": seed + i, "object": objects[i], "success": success, "steps": steps,
                              "success_step": steps if success else None, "outcome": outcome,
                              "min_goal_distance": None if not np.isfinite(closest[i]) else round(closest[i], 4),
                              "grasped_steps": int(grasped_steps[i]), "max_lift": round(lift[i], 4),
                              "final_flange_height": round(float(flange[1]), 4),
                              "max_wrist_force": round(wrist_force[i], 2),
                              "least_grasped_gap": None if not np.isfinite(least_gap[i]) else round(least_gap[i], 4),
                              "final_gap": round(float(info["jaw_gap"]), 4),
                              "pierced_steps": int(pierced_steps[i]),
                              "penetrated_steps": int(penetrated_steps[i]),
                              "max_penetration": round(float(penetration[i]), 6),
                              "median_grasp_quality": round(float(np.median(qualities[i])), 3) if qualities[i] else None,
                              "hold_beyond_pad_faces": None if np.isnan(hold_beyond[i, 0])
                              else [round(float(v), 4) for v in hold_beyond[i]],
                              "pressed_steps": int(pressed_steps[i]),
                              "newton_iterations_median": float(np.median(newton[i])),
                              "newton_iterations_max": int(max(newton[i])),
                              "return": float(info["episode"]["r"])}
    wall = time.perf_counter() - t0
    venv.close()
    return records, wall


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", help="a train_ppo.py output folder (ppo.zip, vecnormalize.pkl, run.json)")
    ap.add_argument("--worlds", type=int, default=32, help="episodes, one per world")
    ap.add_argument("--seed", type=int, default=10**9)
    ap.add_argument("--device", default="cpu", help="simulation device (cpu, cuda:0)")
    ap.add_argument("--torch-device", default="cpu")
    ap.add_argument("--stochastic", action="store_true", help="sample actions instead of the policy's mean")
    ap.add_argument("--object", default=None, type=parse_object,
                    help="evaluate on another object than the run's (names separated by commas: drawn per "
                         "episode; an override gives up a --fixed-world-objects run's assignment)")
    ap.add_argument("--youngs-modulus", type=float, default=None, help="evaluate at another E (Pa) than the run's")
    ap.add_argument("--edge-contact", action=argparse.BooleanOptionalAction, default=None,
                    help="evaluate with (or --no-edge-contact without) the pads' box edges held out of the "
                         "object (PickupConfig.edge_contact; default: the run's)")
    ap.add_argument("--episode-seconds", type=float, default=None,
                    help="evaluate with another time limit (s) than the run's (e.g. the env's default 15 s for "
                         "a run trained on shorter episodes)")
    ap.add_argument("--workers", type=int, default=1,
                    help="processes to spread the worlds over (the same episodes as one process)")
    ap.add_argument("--json", default=None, help="write the result (every episode) to this file")
    args = ap.parse_args(argv)
    if args.workers < 1 or args.worlds < 1:
        ap.error(f"--workers and --worlds must be >= 1, got {args.workers} and {args.worlds}")
    result = evaluate(pathlib.Path(args.run), args.worlds, args.seed, args.device, args.torch_device,
                      deterministic=not args.stochastic, workers=args.workers, object=args.object,
                      youngs_modulus=args.youngs_modulus, edge_contact=args.edge_contact,
                      episode_seconds=args.episode_seconds)
    env = result["env"]
    moduli = env["youngs_modulus"]
    moduli = f"{moduli:g}" if isinstance(moduli, (int, float)) else ", ".join(f"{m:g}" for m in moduli)
    objects = env["object"] if isinstance(env["object"], str) else ", ".join(env["object"])
    print(f"{args.run}: {objects}, E = {moduli} Pa, {args.worlds} episodes "
          f"(seeds {args.seed}..{args.seed + args.worlds - 1}), {'stochastic' if args.stochastic else 'deterministic'} "
          f"policy, {args.device}, {result['wall_s']} s")
    print(f"success {result['outcomes']['success']}/{args.worlds} = {result['success_rate']:.3f}; "
          f"median step of success {result['success_step_median']}")
    for outcome, n in result["outcomes"].items():
        quality = [e["median_grasp_quality"] for e in result["episodes"]
                   if e["outcome"] == outcome and e["median_grasp_quality"] is not None]
        print(f"  {outcome}: {n}" + (f" (grasp quality while grasped, median of the episodes' medians: "
                                     f"{np.median(quality):.2f})" if quality else ""))
    penetrated = [e for e in result["episodes"] if e["penetrated_steps"]]
    print(f"  episodes with steps flagged sim_penetrated: {len(penetrated)}/{args.worlds} "
          f"({sum(e['penetrated_steps'] for e in penetrated)} steps; deepest "
          f"{1e3 * max(e['max_penetration'] for e in result['episodes']):.2f} mm)")
    pressed = [e["pressed_steps"] for e in result["episodes"] if e["pressed_steps"]]
    print(f"  episodes pressing the object beyond the force term's free force: {len(pressed)}/{args.worlds} "
          f"({sum(pressed)} steps); Newton iterations a step: median "
          f"{np.median([e['newton_iterations_median'] for e in result['episodes']]):.0f}, most "
          f"{max(e['newton_iterations_max'] for e in result['episodes'])}")
    beyond = [max(e["hold_beyond_pad_faces"]) for e in result["episodes"] if e["success"]]
    if beyond:
        print(f"  successes held with the feature point > 5 mm beyond the pad faces (off-centre; see "
              f"hold_beyond_pad_faces): {sum(b > 0.005 for b in beyond)}/{len(beyond)}")
    if len(result["outcomes_by_object"]) > 1:
        for name, counts in result["outcomes_by_object"].items():
            total = sum(counts.values())
            print(f"  {name}: success {counts['success']}/{total}; " + ", ".join(
                f"{o} {n}" for o, n in counts.items() if o != "success"))
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
