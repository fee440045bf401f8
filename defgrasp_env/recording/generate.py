"""``defgrasp-generate``: record N episodes per (object, E) with a policy (default: the scripted expert).

    defgrasp-generate OUT --objects cuboid,torus --moduli 1e4,1e5 --episodes 3 [--seed 0] [--worlds 3]

Files are named ``<object>_E<E>_<rep>.h5``; a file that exists is complete (files appear
atomically), so a run interrupted at any moment resumes where it stopped when started again with
the same arguments. Each episode's reset seed derives from ``--seed`` and its file name only, so a
resumed run records exactly what an uninterrupted one would. ``--worlds N`` records up to N episodes
of an (object, E) together, as the worlds of one native vector env (each world steps as a single
env on its seed; on the CPU the files hold the same data as one-by-one recording's, bit for bit).
"""

from __future__ import annotations

import argparse
import copy
import importlib
import inspect
import pathlib
import sys
import zlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..envs.config import PickupConfig
from ..layout import ACTION_LAYOUTS

DEFAULT_POLICY = "defgrasp_env.policies:ScriptedPickupExpert"


@dataclass(frozen=True)
class Job:
    object: str
    youngs_modulus: float
    rep: int
    seed: int

    @property
    def name(self) -> str:
        mantissa, exponent = f"{self.youngs_modulus:.3e}".split("e")
        e_text = f"{float(mantissa):g}e{int(exponent)}"
        return f"{pathlib.Path(self.object).stem}_E{e_text}_{self.rep:03d}.h5"


def plan_jobs(objects: list[str], moduli: list[float], episodes: int, seed: int) -> list[Job]:
    jobs = []
    for obj in objects:
        for e in moduli:
            for rep in range(episodes):
                name = Job(obj, e, rep, 0).name
                s = int(np.random.SeedSequence([seed, zlib.crc32(name.encode())]).generate_state(1)[0])
                jobs.append(Job(obj, e, rep, s))
    return jobs


class RandomPolicy:
    """Uniform random actions from the action space (seeded per episode); for smoke tests. On a
    vector env, one action space per world, seeded with that world's seed (``reset(seed=[...])``),
    so world w draws what a single env seeded like it draws."""

    def __init__(self, env):
        self.space = env.action_space
        self.single = getattr(env, "single_action_space", None)
        self.spaces: list = []

    def reset(self, seed: int | list[int] | None = None) -> None:
        if self.single is None:
            self.space.seed(seed)
            return
        seeds = list(seed) if isinstance(seed, (list, tuple)) else [seed] * self.space.shape[0]
        self.spaces = [copy.deepcopy(self.single) for _ in seeds]
        for space, s in zip(self.spaces, seeds):
            space.seed(s)

    def __call__(self, obs):
        if self.single is None:
            return self.space.sample()
        return np.stack([space.sample() for space in self.spaces])


def load_policy(spec: str, env) -> Callable:
    """A policy (obs -> action) from ``module:attr`` (class with ``from_env``, class taking the env or
    nothing, or a callable) or ``random``."""
    if spec == "random":
        return RandomPolicy(env)
    module, _, attr = spec.partition(":")
    if not attr:
        raise ValueError(f"--policy must be 'module:attribute' or 'random', got {spec!r}")
    try:
        obj = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"policy {spec!r} is not importable ({exc}); pass --policy module:callable") from exc
    if inspect.isclass(obj):
        if hasattr(obj, "from_env"):
            return obj.from_env(env)
        required = [p for p in inspect.signature(obj).parameters.values()
                    if p.default is p.empty and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
        return obj(env) if required else obj()
    if not callable(obj):
        raise TypeError(f"policy {spec!r} is not callable")
    return obj


def _reset_policy(policy, seed: int | list[int]) -> None:
    reset = getattr(policy, "reset", None)
    if callable(reset):
        params = inspect.signature(reset).parameters
        reset(seed=seed) if "seed" in params else reset()


def record_jobs(out: pathlib.Path, jobs: list[Job], policy_spec: str, max_steps: int | None = None,
                device: str = "cpu", record_frames: bool = False, compression: str | None = None,
                on_episode: Callable[[Job, bool], None] | None = None, worlds: int = 1,
                action_mode: str = "delta") -> None:
    """Record ``jobs`` into ``out`` (the recorder named by the job); ``on_episode(job, success)``
    after each. The one place where the recorder is driven: the serial run and each Ray task
    (``distributed.py``) call it. ``worlds`` 1: one env per (object, E), its episodes one after
    the other; > 1: the episodes of an (object, E) in native vector envs of up to ``worlds`` worlds,
    recorded together (each world's episode as a single env on its seed records it; the policy
    must take a batch of observations, as the scripted expert and 'random' do). ``action_mode``: the
    env's (``"delta"``, ``"absolute"`` or ``"topdown"``, ``PickupConfig.action_mode``); the policy
    must act in it (the scripted expert acts in any)."""
    if isinstance(worlds, bool) or not isinstance(worlds, int) or worlds < 1:
        raise ValueError(f"worlds must be an integer >= 1, got {worlds!r}")
    for group in job_groups(jobs, None if worlds == 1 else worlds):
        kwargs = {"object": group[0].object, "youngs_modulus": group[0].youngs_modulus, "device": device,
                  "action_mode": action_mode}
        if max_steps is not None:
            kwargs["max_episode_steps"] = max_steps
        if record_frames:
            kwargs["render_mode"] = "rgb_array"
        record = _record_one_by_one if worlds == 1 else _record_together
        record(out, group, kwargs, policy_spec, record_frames, compression, on_episode)


def job_groups(jobs: list[Job], size: int | None = None) -> list[list[Job]]:
    """``jobs`` grouped by (object, E), in order, each group cut into pieces of at most ``size``
    (None: whole): the episodes one env records (and, on Ray, one task)."""
    groups: dict[tuple[str, float], list[Job]] = {}
    for j in jobs:
        groups.setdefault((j.object, j.youngs_modulus), []).append(j)
    step = size or max(len(jobs), 1)
    return [g[k:k + step] for g in groups.values() for k in range(0, len(g), step)]


def _record_one_by_one(out, group: list[Job], kwargs: dict, policy_spec: str, record_frames: bool,
                       compression: str | None, on_episode) -> None:
    """The ``group``'s episodes one after the other in one single env made with ``kwargs``."""
    import gymnasium as gym

    from .. import ENV_ID
    from .recorder import HDF5Recorder

    env = HDF5Recorder(gym.make(ENV_ID, **kwargs), out, record_frames=record_frames, compression=compression,
                       save_unfinished=False, policy=policy_spec)
    policy = load_policy(policy_spec, env)
    try:
        for job in group:
            env.set_next_name(job.name)
            _reset_policy(policy, job.seed)
            obs, _ = env.reset(seed=job.seed)
            done = False
            while not done:
                obs, _, terminated, truncated, _ = env.step(policy(obs))
                done = terminated or truncated
            if on_episode is not None:
                on_episode(job, bool(terminated))
    finally:
        env.close()


def _record_together(out, group: list[Job], kwargs: dict, policy_spec: str, record_frames: bool,
                     compression: str | None, on_episode) -> None:
    """The ``group``'s episodes at once, world w of a native vector env (made with ``kwargs``,
    autoreset off) reset with job w's seed; a batched policy (a ``reset(seed)`` gets the worlds'
    seeds as a list). A world whose episode ended is stepped on with the others (lockstep), unrecorded;
    the policy sees its final observation, not what it does after."""
    import gymnasium as gym
    import numpy as np
    from gymnasium.vector import AutoresetMode

    from .. import ENV_ID
    from .vector_recorder import VectorHDF5Recorder

    if record_frames:
        raise ValueError("--frames records one episode at a time: use --worlds 1")
    n = len(group)
    env = VectorHDF5Recorder(gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point",
                                          autoreset_mode=AutoresetMode.DISABLED, **kwargs),
                             out, compression=compression, save_unfinished=False, policy=policy_spec)
    try:
        policy = load_policy(policy_spec, env)
        for w, job in enumerate(group):
            env.set_next_name(job.name, w)
        seeds = [job.seed for job in group]
        _reset_policy(policy, seeds)
        obs, _ = env.reset(seed=seeds)
        done = np.zeros(n, bool)
        final = {k: np.array(v) for k, v in obs.items()}
        while not done.all():
            seen = {k: np.where(done.reshape((n,) + (1,) * (v.ndim - 1)), final[k], v) for k, v in obs.items()}
            action = policy(seen)
            if np.shape(action) != env.action_space.shape:
                raise ValueError(f"policy {policy_spec!r} returned actions of shape {np.shape(action)} for {n} worlds; "
                                 f"--worlds > 1 needs a policy that maps a batch of observations to actions "
                                 f"{env.action_space.shape} (as the scripted expert does): use --worlds 1")
            obs, _, terminated, truncated, _ = env.step(action)
            for w in np.flatnonzero(~done & (terminated | truncated)):
                done[w] = True
                for k, v in obs.items():
                    final[k][w] = v[w]
                if on_episode is not None:
                    on_episode(group[w], bool(terminated[w]))
    finally:
        env.close()


def progress_bar(total: int, finished: int, enabled: bool):
    """A tqdm bar over episodes (None when disabled) and its per-episode callback."""
    if not enabled:
        return None, None
    from tqdm import tqdm

    bar = tqdm(total=total, initial=finished, unit="episode", desc="defgrasp-generate")

    def on_episode(job: Job, success: bool) -> None:
        bar.update(1)
        bar.set_postfix_str(f"last: {job.name} {'success' if success else 'no success'}")

    return bar, on_episode


def check_same_recording_config(out: pathlib.Path, action_mode: str = "delta", policy: str | None = None) -> None:
    """Resuming into ``out`` must record what an uninterrupted run would have, and a folder is one
    dataset: raise ValueError if an episode file already there (any of them: a run records all its
    files with one config) was recorded with another pad contact model than today's default
    (``PickupConfig.edge_contact``, on since 2026-11-26; files from before lack the key and were
    recorded without it), in another ``action_mode`` than this run's, or by another ``policy``
    (its ``policy`` attribute; files from before 2026-11-27 lack it and are not checked), naming
    the file."""
    import h5py

    from ..envs.config import PickupConfig
    from .checks import attr_value
    from .config_io import config_from_json
    from .reader import list_episodes

    files = list_episodes(out) if pathlib.Path(out).is_dir() else []
    if not files:
        return
    path = files[0]
    with h5py.File(path, "r") as f:
        recorded = config_from_json(str(f.attrs["config_json"]))
    default = PickupConfig().edge_contact
    if recorded.edge_contact != default:
        raise ValueError(f"{path} was recorded with edge_contact={recorded.edge_contact}, today's default is "
                         f"{default} (pad edge contact): resuming would mix contact models in one dataset; "
                         "record into a new folder")
    if recorded.action_mode != action_mode:
        raise ValueError(f"{path} was recorded with action_mode={recorded.action_mode!r}, this run's is "
                         f"{action_mode!r}: the folder would mix action layouts in one dataset; pass "
                         f"--action-mode {recorded.action_mode} or record into a new folder")
    if policy is None:
        return
    for other in files:
        with h5py.File(other, "r") as f:
            recorded_policy = attr_value(f.attrs.get("policy", policy))
        if recorded_policy != policy:
            raise ValueError(f"{other} was recorded by the policy {recorded_policy!r}, this run's is {policy!r}: "
                             "the folder would mix policies in one dataset; record into a new folder"
                             + ("" if recorded_policy == "teleop" else f" or pass --policy {recorded_policy}"))


def run_jobs(out: pathlib.Path, jobs: list[Job], policy_spec: str, max_steps: int | None = None,
             device: str = "cpu", record_frames: bool = False, compression: str | None = None,
             progress: bool = True, worlds: int = 1, action_mode: str = "delta") -> list[pathlib.Path]:
    """Record every job whose file is missing (``worlds`` episodes of an (object, E) at once, in
    ``action_mode``, see ``record_jobs``); return the files of all jobs."""
    from .atomic import check_writable_directory, remove_stale_temps

    check_writable_directory(out)
    remove_stale_temps(out)
    todo = [j for j in jobs if not (out / j.name).exists()]
    bar, on_episode = progress_bar(len(jobs), len(jobs) - len(todo), progress)
    try:
        record_jobs(out, todo, policy_spec, max_steps, device, record_frames, compression, on_episode, worlds,
                    action_mode)
    finally:
        if bar is not None:
            bar.close()
    return [out / j.name for j in jobs]


def summary_table(paths: list[pathlib.Path]) -> str:
    """Per (object, E): episodes, success rate, mean length (steps) and mean return."""
    import h5py

    rows: dict[tuple[str, float], list[tuple[bool, int, float]]] = {}
    for p in paths:
        with h5py.File(p, "r") as f:
            key = (pathlib.Path(str(f.attrs["object_name"])).stem, float(f["object/youngs_modulus"][()]))
            rows.setdefault(key, []).append((bool(f.attrs["is_success"]), int(f.attrs["num_steps"]),
                                             float(np.sum(f["steps/reward"][()]))))
    lines = [f"{'object':10s} {'E [Pa]':>8s} {'episodes':>8s} {'success':>8s} {'steps':>7s} {'return':>8s}"]
    total = []
    for (obj, e), r in sorted(rows.items()):
        total += r
        s, n, ret = np.array([x[0] for x in r]), np.array([x[1] for x in r]), np.array([x[2] for x in r])
        lines.append(f"{obj:10s} {e:8.0e} {len(r):8d} {s.mean():8.2f} {n.mean():7.1f} {ret.mean():8.2f}")
    if total:
        s = np.array([x[0] for x in total])
        lines.append(f"{'all':10s} {'':8s} {len(total):8d} {s.mean():8.2f} "
                     f"{np.mean([x[1] for x in total]):7.1f} {np.mean([x[2] for x in total]):8.2f}")
    return "\n".join(lines)


def _floats(text: str) -> list[float]:
    try:
        return [float(x) for x in text.split(",") if x]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def main(argv: list[str] | None = None) -> int:
    from .cli import default_caches

    p = argparse.ArgumentParser(prog="defgrasp-generate", description=__doc__.split("\n")[0])
    p.add_argument("out", type=pathlib.Path, help="output folder of episode files (resumable)")
    p.add_argument("--objects", default="cuboid,sphere,torus,cylinder,rope", help="comma-separated names or mesh paths")
    p.add_argument("--moduli", type=_floats, default=[1e4, 1e5, 1e6, 1e7], help="comma-separated E values, Pa")
    p.add_argument("--episodes", type=int, default=1, help="episodes per (object, E)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-steps", type=int, default=None, help="episode step limit (default: the env's 15 s)")
    p.add_argument("--policy", default=DEFAULT_POLICY, help="module:callable, or 'random'")
    p.add_argument("--frames", action="store_true", help="also record camera frames")
    p.add_argument("--action-mode", choices=list(ACTION_LAYOUTS), default="delta",
                   help="the env's action mode (absolute: target flange pose and gap; topdown: velocities, "
                        "target yaw and jaw; e.g. for imitation)")
    p.add_argument("--compression", choices=["gzip", "lzf"], default=None)
    p.add_argument("--device", default="cpu")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                   help="record on a Ray cluster: 'auto' (the one `ray start` made), an address, or no "
                        "value for a local Ray on this machine (needs defgrasp[ray])")
    p.add_argument("--worlds", type=int, default=1,
                   help="episodes of one (object, E) recorded together in a native vector env of this many "
                        "worlds (per process; with --ray per worker); the policy must take batched observations")
    p.add_argument("--workers", type=int, default=None,
                   help="with --ray: Ray tasks at once, each an episode or (--worlds N) a group of N "
                        "(default: one per CPU, or per GPU with --device cuda)")
    args = p.parse_args(argv)
    default_caches()
    if args.episodes < 1 or args.worlds < 1 or (args.max_steps is not None and args.max_steps < 1):
        p.error(f"--episodes, --worlds and --max-steps must be >= 1, got {args.episodes}, {args.worlds}, "
                f"{args.max_steps}")
    if args.worlds > 1 and args.frames:
        p.error("--frames records one episode at a time: use --worlds 1")
    if args.workers is not None and (args.workers < 1 or args.ray is None):
        p.error(f"--workers needs --ray and must be >= 1, got {args.workers}")
    objects = [o for o in args.objects.split(",") if o]
    if not objects or not args.moduli:
        p.error(f"--objects and --moduli must name at least one value each, got {args.objects!r} and {args.moduli}")
    try:  # before anything runs or is written: the names, mesh files and moduli, as the env checks them
        PickupConfig(object=tuple(objects), youngs_modulus=tuple(args.moduli))
    except (ValueError, TypeError) as exc:
        p.error(str(exc))
    jobs = plan_jobs(objects, args.moduli, args.episodes, args.seed)
    record = run_jobs
    if args.ray is not None:
        from functools import partial

        from .distributed import run_jobs_ray
        record = partial(run_jobs_ray, address=None if args.ray == "local" else args.ray, workers=args.workers)
    try:
        check_same_recording_config(args.out, args.action_mode, args.policy)
        paths = record(args.out, jobs, args.policy, args.max_steps, args.device, args.frames,
                       args.compression, progress=not args.no_progress, worlds=args.worlds,
                       action_mode=args.action_mode)
    except KeyboardInterrupt:
        print("\ninterrupted: finished episodes are kept; run the same command again to resume", file=sys.stderr)
        return 130
    except (OSError, ValueError, TypeError, ImportError, RuntimeError) as exc:
        print(f"defgrasp-generate: error: {exc}", file=sys.stderr)
        return 2
    print(summary_table(paths))
    return 0


if __name__ == "__main__":
    sys.exit(main())
