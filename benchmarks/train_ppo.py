"""PPO (Stable-Baselines3) learning the lift from scratch on the native vector env.

N worlds of ``gym.make_vec("DeformablePickup-v0", num_envs=N, autoreset_mode="SameStep")`` (one
batched FEM simulation, on the CPU or a CUDA device) drive SB3's PPO through
``defgrasp_env.rl.SB3VectorEnv``, with ``VecMonitor`` (episode returns, ``is_success``) and
``VecNormalize`` (running observation / reward normalisation). The env's dense reward is used as
is (reach + grasp + lift + place + success + force; see ``DeformablePickupEnv``). After every PPO rollout the
script records the env steps so far, wall time, the success rate and mean return of the
episodes that ended in that rollout (the stochastic training policy; with worlds that begin their
episodes together this rate swings: successes end early, failures all at the time limit), the
success rate of the cohort of episodes that began one time limit before the rollout (all ended:
unbiased, for the policy of one episode earlier), the fraction of its
world-steps with the object grasped and grasped within the success tolerance of the goal, the
median / p95 time of its vector steps and the slowest world's Newton / CG iterations per step
(median over the rollout); at the end it prints the learning curve as a table and writes
``curve.csv`` and ``curve.png`` (success and grasp vs env steps and vs wall time) to ``--out``, the
model to ``--out/ppo.zip``, the observation/reward normalisation to ``--out/vecnormalize.pkl`` and
the run's settings to ``--out/run.json``, and the policy of the rollout with the best cohort rate
(over >= ``--best-min-episodes`` episodes) to ``--out/best`` as the same files (``BestPolicy``);
``--resume DIR`` goes on from such a folder (model,
normalisation and curve continue; the env and PPO options, ``--seed`` included, must be the run's;
the env is seeded with ``--seed`` + the env steps so far, so the resumed run does not replay the
earlier episodes). ``eval_ppo.py`` evaluates a saved run on fresh episodes (one per world).

``--actions position-jaw`` (``defgrasp_env.rl.action_subset``) lets the policy move the wrist
and the jaw but not turn the wrist (4 actions instead of 7); ``position-yaw-jaw`` also turns it
about the vertical (5). ``--object cuboid,sphere,torus,cylinder,rope --fixed-world-objects`` trains
on the five objects at once, each in a fifth of the worlds for every episode (no model rebuild at
the autoresets, which a draw per episode would cost at nearly every step). ``--init-from`` may
start from a run with another action set (its action head is mapped by component). ``--goal-noise``
draws each training episode's goal around ``--goal`` (``PickupConfig.goal_noise``; the goal is in the
observation): goals from near the ground up make the lift pay from its first centimetres, where
the fixed 0.6 m goal's reward barely changes (a policy from scratch learned to hold the cube on the
ground and not to lift it, benchmarks/RESULTS.md); the curve then also reports the cohort's
episodes whose goal lies at the task's (within the success tolerance of the default 0, 0.6, 0),
and ``eval_ppo.py`` evaluates at the task's goal. ``--no-terminate-on-success``
(``PickupConfig.terminate_on_success``) lets a training episode go on after its success, the bonus
repeating while the object stays at the goal (an episode counts as a success if any step was):
where a success ends the episode, circling through the goal is worth about as much (RESULTS.md).
Its episodes all last the time limit, so worlds reset together stay in phase and each rollout
holds one phase of the task: ``--stagger-episodes`` cuts each world's first episode at a random
step (``SB3VectorEnv(stagger_first_episodes=True)``; the curve leaves the first episodes out). In
phase, a fine-tune's success fell from 0.91 to 0.79 in 1.5 M steps; staggered it stayed at 0.91-0.96 after its first cohort
(RESULTS.md, 2026-11-27). Such a run's curve also reports the holding rate: the fraction of each
rollout's world-steps at least ``HOLDING_SECONDS`` into their episode that hold the object at the
goal (``is_success``), over all worlds and per object (``LearningCurve.holding_steps``). It reads in a
session shorter than an episode, where no cohort has ended (the five objects' ~8-minute device
sessions of 2026-11-28: 125-160 steps per world against 240-step episodes).
Goals lower than the object's feature point
plus the success tolerance (~0.07 m for the cuboid) succeed on a grasp without a lift: the
curriculum's first step. ``--out/best`` is then chosen by the success rate at the task's goal, pooled
over the latest rollouts' cohorts back to 256 such episodes (``TASK_GOAL_RANKING``). A run ``--init-from`` one
trained at a fixed goal starts with the normalisation statistics of a constant goal: its goal
inputs saturate until the running variance catches up. ``--clone-expert-steps T`` starts a new run from the scripted expert instead of random weights
(``ExpertClone``, ``defgrasp_env.rl.expert_cloning``: T vector steps of the noise-injected expert
in this run's env, the policy's mean fitted to its actions and its value to the complete returns;
``--timesteps 0`` saves the clone alone). A fine-tune of such a policy wants
``--freeze-obs-normalisation``: with the statistics updating, PPO from the clone held every object
0.1 m below the goal (the object height's running mean had fallen 0.09 m; RESULTS.md, 2026-12-06);
``--policy-std`` sets the start's std (a clone's is its data's small noise). The PPO
settings default to those ManiSkill's PPO baseline uses for its pick tasks with dense rewards (gamma 0.8, GAE lambda 0.9,
8 epochs of 32 minibatches per rollout, 3 x 256 networks, initial log std -0.5, target KL 0.1);
fewer minibatches where a rollout is too small for 64 samples in each (small CPU runs).

    python benchmarks/train_ppo.py --num-envs 16 --timesteps 200000 --object cuboid --youngs-modulus 1e6
    python benchmarks/train_ppo.py --num-envs 256 --device cuda:0 --timesteps 5000000   # at scale
    python benchmarks/train_ppo.py --num-envs 2048 --device cuda:0 --torch-device cuda --actions position-yaw-jaw \
        --episode-seconds 6 --goal 0 0.35 0 --goal-noise 0 0.3 0 --minutes 9   # from scratch, drawn goals
    python benchmarks/train_ppo.py --num-envs 2048 --device cuda:0 --torch-device cuda --actions position-yaw-jaw \
        --episode-seconds 12 --goal 0 0.4 0 --goal-noise 0 0.35 0 --no-terminate-on-success --stagger-episodes \
        --init-from benchmarks/policies/ppo_cuboid_scratch_goal_noise_e1e6 --minutes 5   # the hold
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import pathlib
import shutil
import sys
import time
from dataclasses import dataclass

ROOT = pathlib.Path(__file__).resolve().parents[1]
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402


class BestPolicy:
    """Keeps, in ``folder``, the policy of the rollout with the highest cohort success rate so far
    (over at least ``min_episodes`` episodes): ``ppo.zip``, ``vecnormalize.pkl`` and ``run.json`` as
    ``save_run`` writes them (``eval_ppo.py`` evaluates the folder), and ``best.json`` (the row's env
    steps, wall time, cohort rate and episodes). A cohort's episodes began one time limit earlier, so
    they ran under the policies of the rollouts since; the one kept is the latest of those.
    ``resumed``: the folder's kept policy (a ``best.json``) is this run's, and only a better rate
    replaces it; otherwise a kept policy there (of an earlier run into the same ``--out``) is removed.
    Each save writes a new folder and then swaps it in, so a crash leaves the old or the new policy
    whole (or both, as ``folder`` and ``folder.old``). Why: a PPO fine-tune's cohort rate here rose to
    0.68 (over 1,379 episodes) and ended at 0.3 (benchmarks/RESULTS.md): the last policy alone is not
    the run's best. ``rate_key`` / ``episodes_key``: the row's columns that rank the policies (a run
    on drawn goals ranks by the pooled rate of its episodes at the task's goal:
    ``TASK_GOAL_RANKING``)."""

    def __init__(self, folder: pathlib.Path, min_episodes: int = 256, resumed: bool = False,
                 rate_key: str = "cohort_success_rate", episodes_key: str = "cohort_episodes"):
        if min_episodes < 1:
            raise ValueError(f"min_episodes must be >= 1, got {min_episodes}")
        self.folder = pathlib.Path(folder)
        self.min_episodes = min_episodes
        self.rate_key, self.episodes_key = rate_key, episodes_key
        self.rate = float("-inf")
        marker = self.folder / "best.json"
        if resumed and marker.is_file():
            self.rate = json.loads(marker.read_text())[rate_key]
        elif marker.is_file():
            shutil.rmtree(self.folder)

    def offer(self, model, row: dict, settings: dict) -> bool:
        """Save ``model`` if ``row`` (a ``LearningCurve`` row) beats the kept rate; True if saved."""
        rate, episodes = row.get(self.rate_key, float("nan")), row.get(self.episodes_key, 0)
        if episodes < self.min_episodes or not rate > self.rate:
            return False
        new, old = self.folder.with_name(self.folder.name + ".new"), self.folder.with_name(self.folder.name + ".old")
        shutil.rmtree(new, ignore_errors=True)
        new.mkdir(parents=True)
        save_policy(model, settings, new)
        keep = {k: row[k] for k in dict.fromkeys(("env_steps", "wall_s", "cohort_success_rate", "cohort_episodes",
                                                  self.rate_key, self.episodes_key))}
        (new / "best.json").write_text(json.dumps(keep, indent=1) + "\n")
        shutil.rmtree(old, ignore_errors=True)
        if self.folder.exists():
            self.folder.rename(old)
        new.rename(self.folder)
        shutil.rmtree(old, ignore_errors=True)
        self.rate = rate
        return True


#: The columns a run on drawn goals ranks its policies by (``BestPolicy``): the success rate of the
#: latest episodes at the task's goal, pooled over the fewest latest rollouts' cohorts that hold
#: ``LearningCurve.pool_episodes`` of them (one rollout's cohort holds too few: ~1/6 of its episodes).
TASK_GOAL_RANKING = ("task_goal_pooled_success_rate", "task_goal_pooled_episodes")
#: s: with ``--no-terminate-on-success`` the curve's holding rate counts the world-steps this far into
#: their episode (``LearningCurve.holding_steps``): the shipped cuboid policy succeeds at a median 3.1 s,
#: the five-object policies at ~3.2 s, the scripted expert at 3.8-5.4 s.
HOLDING_SECONDS = 5.0


class LearningCurve(BaseCallback):
    """Success rate and mean return of the episodes that ended in each rollout, vs env steps and wall time."""

    def __init__(self, settings: dict, env_seed: int, max_seconds: float = float("inf"),
                 rows: list[dict] | None = None, success_tolerance: float = 0.05, episode_steps: int = 300,
                 best: BestPolicy | None = None, task_goal=None, pool_episodes: int = 256,
                 holding_steps: int | None = None):
        super().__init__()
        #: vector steps, or None: where successes do not end episodes, each rollout also reports the
        #: fraction of its world-steps at least this far into their episode that have held the object
        #: at the goal for the success hold (``is_success``), over all worlds and per object: ``holding_rate`` and
        #: ``holding_rate_<object>``. Unlike the cohort rate it needs no episode to end, so a session
        #: shorter than an episode (every session restarts all episodes) still reads it
        self.holding_steps = holding_steps
        self._holding: dict[str, list[bool]] = {}  # object -> is_success of this rollout's old-enough world-steps
        self._objects: list[str] | None = None  # each world's object in its current episode
        self.pool_episodes = pool_episodes  # episodes at the task's goal the pooled rate reaches back for
        #: m [3], or None: where training goals are drawn (``--goal-noise``), the cohort's episodes
        #: whose goal lies within the success tolerance of this one (the task's) are also counted apart
        self.task_goal = None if task_goal is None else np.asarray(task_goal, dtype=np.float64)
        self.best = best  # keeps the policy of the best cohort rate (None: not kept)
        self.episode_steps = episode_steps  # the env's time limit (vector steps): every episode has ended this long after its start
        self.success_tolerance = success_tolerance  # m: the env's; "at goal" = grasped and this close
        self.settings = dict(settings)  # the run's env and PPO options and its --seed (run.json)
        self.env_seed = env_seed  # the seed of this session's env: --seed + the env steps of earlier sessions
        self.max_seconds = max_seconds  # training stops at the first step after this wall time
        self.rows: list[dict] = list(rows or [])  # a resumed run's earlier rows; wall time goes on from them
        self._wall0 = self.rows[-1]["wall_s"] if self.rows else 0.0
        # (successes, episodes) of each row's cohort at the task's goal, latest last (a resumed run's too)
        self._task_pool = [(round(r["task_goal_cohort_success_rate"] * n), n) for r in self.rows
                           if (n := r.get("task_goal_cohort_episodes", 0)) and n == n and n > 0]
        self._success: list[bool] = []
        self._returns: list[float] = []
        self._grasped: list[float] = []
        self._at_goal: list[float] = []  # fraction of each step's worlds grasped within the success tolerance of the goal
        self._step_s: list[float] = []  # wall time of each vector step of the rollout (policy + env)
        self._slowest: list[tuple[int, int]] = []  # (Newton, CG) iterations of the step's slowest world
        self._t0 = time.perf_counter()
        self._rollout_t0 = self._t0
        self._step_t0 = self._t0
        self._steps = 0  # vector steps of this session
        self._starts: np.ndarray | None = None  # [N] the vector step at which each world's episode began
        self._ended: list[tuple[int, bool, bool]] = []  # (start step, success, at the task goal) of the episodes not yet in a cohort
        self._near_task: np.ndarray | None = None  # [N] bool: the world's episode has a goal at the task's
        self._succeeded: np.ndarray | None = None  # [N] bool: a step of the world's episode succeeded

    def _on_rollout_start(self) -> None:
        self._rollout_t0 = self._step_t0 = time.perf_counter()

    def _on_step(self) -> bool:
        infos = self.locals["infos"]
        now = time.perf_counter()
        self._step_s.append(now - self._step_t0)
        self._step_t0 = now
        self._slowest.append((max(int(info.get("newton_iterations", 0)) for info in infos),
                              max(int(info.get("cg_iterations", 0)) for info in infos)))
        self._grasped.append(float(np.mean([bool(info.get("grasped", False)) for info in infos])))
        self._at_goal.append(float(np.mean([bool(info.get("grasped", False)) and info.get("goal_distance", np.inf)
                                            < self.success_tolerance for info in infos])))
        if self._starts is None:
            self._starts = np.zeros(len(infos), int)
            self._near_task = np.array([self._at_task_goal(w) for w in range(len(infos))])
            self._succeeded = np.zeros(len(infos), bool)
        self._steps += 1
        # an episode succeeded if any of its steps did (its last one, unless successes do not terminate)
        self._succeeded |= np.array([bool(info.get("is_success", False)) for info in infos])
        if self.holding_steps is not None:
            if self._objects is None:
                self._objects = [self._episode_object(w) for w in range(len(infos))]
            for world in np.flatnonzero(self._steps - self._starts >= self.holding_steps):
                self._holding.setdefault(self._objects[world], []).append(bool(infos[world].get("is_success", False)))
        for world, (done, info) in enumerate(zip(self.locals["dones"], infos)):
            if done and self._objects is not None:
                self._objects[world] = self._episode_object(world)
            if done and info.get("staggered_start", False):  # a staggered first episode: cut or kept by its end
                self._succeeded[world] = False
                self._starts[world] = self._steps
                self._near_task[world] = self._at_task_goal(world)
            elif done:
                self._success.append(bool(self._succeeded[world]))
                self._succeeded[world] = False
                self._returns.append(float(info.get("episode", {}).get("r", np.nan)))
                self._ended.append((int(self._starts[world]), self._success[-1], bool(self._near_task[world])))
                self._starts[world] = self._steps
                self._near_task[world] = self._at_task_goal(world)
        return time.perf_counter() - self._t0 < self.max_seconds

    def _at_task_goal(self, world: int) -> bool:
        """Whether world ``world``'s current episode (its reset info's ``goal``) has its goal within
        the success tolerance of ``task_goal`` (False where that is not tracked)."""
        if self.task_goal is None:
            return False
        goal = np.asarray(self._reset_info(world)["goal"], dtype=np.float64)
        return bool(np.linalg.norm(goal - self.task_goal) < self.success_tolerance)

    def _episode_object(self, world: int) -> str:
        """World ``world``'s object in its current episode (its reset info's ``object``)."""
        return str(self._reset_info(world)["object"])

    def _reset_info(self, world: int) -> dict:
        """The reset info of world ``world``'s current episode, from the innermost env."""
        env = self.training_env
        while hasattr(env, "venv"):  # VecNormalize -> VecMonitor -> (ActionSubset) -> SB3VectorEnv
            env = env.venv
        return env.reset_infos[world]

    def _on_rollout_end(self) -> None:
        n = len(self._success)
        cohort, task_cohort = self._cohort()
        self.rows.append({"env_steps": self.num_timesteps, "wall_s": round(self._wall0 + time.perf_counter() - self._t0, 1),
                          "episodes": n, "success_rate": float(np.mean(self._success)) if n else float("nan"),
                          "mean_return": float(np.nanmean(self._returns)) if n else float("nan"),
                          "grasped_fraction": float(np.mean(self._grasped)) if self._grasped else float("nan"),
                          "at_goal_fraction": float(np.mean(self._at_goal)) if self._at_goal else float("nan"),
                          "cohort_episodes": len(cohort),
                          "cohort_success_rate": float(np.mean(cohort)) if cohort else float("nan"),
                          **({} if self.task_goal is None else self._task_columns(task_cohort)),
                          **self._holding_columns(),
                          # seconds of this rollout's collection (env steps + policy forward passes)
                          "rollout_s": round(time.perf_counter() - self._rollout_t0, 2),
                          **self._step_costs()})
        r = self.rows[-1]
        if self.best is not None and self.best.offer(self.model, r, self.settings):
            print(f"best cohort success so far: {r['cohort_success_rate']:.3f} [{r['cohort_episodes']}], saved to "
                  f"{self.best.folder}", flush=True)
        print(f"steps {r['env_steps']:>9d}  wall {r['wall_s']:>8.1f} s  episodes {n:>4d}  "
              f"success {r['success_rate']:.2f}  return {r['mean_return']:.1f}  grasped {r['grasped_fraction']:.3f}  "
              f"at goal {r['at_goal_fraction']:.3f}  cohort success {r['cohort_success_rate']:.2f} "
              f"[{r['cohort_episodes']}]  "
              + (f"at the task goal {r['task_goal_cohort_success_rate']:.2f} [{r['task_goal_cohort_episodes']}] "
                 f"(pooled {r['task_goal_pooled_success_rate']:.2f} [{r['task_goal_pooled_episodes']}])  "
                 if self.task_goal is not None else "")
              + (f"holding after {self.holding_steps} steps {r['holding_rate']:.2f} [{r['holding_world_steps']}] ("
                 + ", ".join(f"{k[len('holding_rate_'):]} {v:.2f}" for k, v in r.items() if k.startswith("holding_rate_"))
                 + ")  " if self.holding_steps is not None else "")
              + f"collection {r['rollout_s']:.1f} s  step p50/p95 {r['step_ms_p50']:.0f}/{r['step_ms_p95']:.0f} ms  "
              f"slowest world Newton {r['slowest_newton']:.0f} CG {r['slowest_cg']:.0f}",
              flush=True)
        self._success, self._returns, self._grasped, self._at_goal, self._step_s, self._slowest = [], [], [], [], [], []
        self._holding = {}

    def _holding_columns(self) -> dict:
        """The row's holding columns (``holding_steps``; none where it is None): world-steps counted,
        their fraction with ``is_success`` (held at the goal for the success hold), and that fraction per
        object (an object without such world-steps in this rollout has no column in the row; curve.csv
        writes nan there)."""
        if self.holding_steps is None:
            return {}
        held = [h for values in self._holding.values() for h in values]
        return {"holding_world_steps": len(held), "holding_rate": float(np.mean(held)) if held else float("nan"),
                **{f"holding_rate_{name}": float(np.mean(values)) for name, values in sorted(self._holding.items())}}

    def _task_columns(self, task_cohort: list[bool]) -> dict:
        """The row's columns of the episodes at the task's goal: this rollout's cohort, and the rate
        pooled over the latest cohorts back to ``pool_episodes`` episodes (all there are, before)."""
        if task_cohort:
            self._task_pool.append((sum(task_cohort), len(task_cohort)))
        successes = episodes = 0
        for s, n in reversed(self._task_pool):
            if episodes >= self.pool_episodes:
                break
            successes, episodes = successes + s, episodes + n
        return {"task_goal_cohort_episodes": len(task_cohort),
                "task_goal_cohort_success_rate": float(np.mean(task_cohort)) if task_cohort else float("nan"),
                TASK_GOAL_RANKING[1]: episodes,
                TASK_GOAL_RANKING[0]: successes / episodes if episodes else float("nan")}

    def _cohort(self) -> tuple[list[bool], list[bool]]:
        """Success of the episodes that began in the window of vector steps that ended a time limit
        ago (of the length of a rollout): all of them have ended, short successful ones and long
        failed ones alike, so their success rate is unbiased (the rate among episodes that merely
        *ended* in a rollout over-represents early successes), for the policy of ~one episode ago.
        Per session: a resumed run's env is reset, so its first rows have no cohort (nan) and the
        episodes begun in a session's last time limit are not counted. Returns the cohort's
        successes and those of its episodes at the task goal (``task_goal``)."""
        now = self._steps - self.episode_steps
        begin = now - self.model.n_steps
        cohort = [(success, near) for start, success, near in self._ended if begin <= start < now]
        self._ended = [item for item in self._ended if item[0] >= now]
        return [success for success, _ in cohort], [success for success, near in cohort if near]

    def _step_costs(self) -> dict:
        """Median / p95 ms of the rollout's vector steps (policy forward pass + env step) and the median
        over its steps of the slowest world's Newton and CG iterations (what a batched step waits for)."""
        if not self._step_s:
            return {"step_ms_p50": float("nan"), "step_ms_p95": float("nan"),
                    "slowest_newton": float("nan"), "slowest_cg": float("nan")}
        ms = 1e3 * np.asarray(self._step_s)
        slowest = np.asarray(self._slowest, float)
        return {"step_ms_p50": round(float(np.median(ms)), 1), "step_ms_p95": round(float(np.percentile(ms, 95)), 1),
                "slowest_newton": float(np.median(slowest[:, 0])), "slowest_cg": float(np.median(slowest[:, 1]))}


def cycled_objects(num_envs: int, **env_kwargs) -> tuple[str, ...]:
    """World i's object for ``--fixed-world-objects``: the config's objects in turn (i mod their count)."""
    from defgrasp_env import PickupConfig

    names = PickupConfig(**env_kwargs).object_names
    return tuple(names[i % len(names)] for i in range(num_envs))


def make_vec_env(num_envs: int, seed: int, actions: str = "full", gamma: float = 0.99,
                 fixed_world_objects: bool = False, stagger_episodes: bool = False,
                 shard_devices: list[str] | None = None, **env_kwargs):
    """The SB3 view of the native vector env (``actions``: a key of
    ``defgrasp_env.rl.action_subset.ACTION_SETS``), with episode statistics and running
    normalisation of observations and rewards (discount ``gamma``).
    ``fixed_world_objects``: world i holds ``cycled_objects(...)[i]`` in every episode (the vector
    env's ``world_objects``: no model rebuild at autoresets), instead of a draw per episode.
    ``stagger_episodes``: ``SB3VectorEnv(stagger_first_episodes=True)``. ``shard_devices`` (two or
    more): the worlds split over one vector env per entry, stepped in threads
    (``defgrasp_env.make_sharded_vec``: ``["cpu", "cpu"]`` uses two CPU cores, ``["cuda:0",
    "cuda:1"]`` two GPUs); the same episodes as one vector env, bit for bit on the CPU."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from defgrasp_env import PickupConfig
    from defgrasp_env.rl.action_subset import ACTION_SETS, ActionSubset
    from defgrasp_env.rl.sb3_vec_env import SB3VectorEnv

    if actions not in ACTION_SETS:
        raise ValueError(f"actions must be one of {sorted(ACTION_SETS)}, got {actions!r}")
    # gym.make_vec passes the registered 300-step limit on: derive it from the options instead
    steps = PickupConfig(**env_kwargs).max_episode_steps
    world_objects = cycled_objects(num_envs, **env_kwargs) if fixed_world_objects else None
    if shard_devices is not None and len(shard_devices) > 1:
        from defgrasp_env import make_sharded_vec

        kwargs = {k: v for k, v in env_kwargs.items() if k != "device"}
        env = make_sharded_vec(num_envs, shard_devices, autoreset_mode="SameStep", max_episode_steps=steps,
                               world_objects=world_objects, **kwargs)
    else:
        env = gym.make_vec("DeformablePickup-v0", num_envs=num_envs, autoreset_mode="SameStep",
                           max_episode_steps=steps, world_objects=world_objects, **env_kwargs)
    venv = SB3VectorEnv(env, stagger_first_episodes=stagger_episodes)
    venv.seed(seed)
    if actions != "full":
        venv = ActionSubset(venv, ACTION_SETS[actions])
    return VecNormalize(VecMonitor(venv, info_keywords=("is_success",)), clip_obs=10.0, gamma=gamma)


def load_normalisation(folder: pathlib.Path, venv, gamma: float | None = None):
    """The observation/reward normalisation saved in ``folder`` (``vecnormalize.pkl``) around the
    ``venv`` a new ``make_vec_env`` built (its ``.venv``: the VecMonitor), keeping this env's action
    space (VecNormalize pickles the saved run's, which differs for another action set) and, if
    given, this run's discount ``gamma`` for the return normalisation."""
    from stable_baselines3.common.vec_env import VecNormalize

    loaded = VecNormalize.load(str(pathlib.Path(folder) / "vecnormalize.pkl"), venv.venv)
    loaded.action_space = loaded.venv.action_space
    if gamma is not None:
        loaded.gamma = gamma
    return loaded


#: ``curve.csv`` columns that are counts (an older run's rows lack the later ones: "nan").
COUNT_COLUMNS = ("env_steps", "episodes", "cohort_episodes", "task_goal_cohort_episodes", "task_goal_pooled_episodes",
                 "holding_world_steps")


def read_curve(folder: pathlib.Path) -> list[dict]:
    """The rows of ``folder/curve.csv`` (as ``LearningCurve`` writes them)."""
    with open(pathlib.Path(folder) / "curve.csv", newline="") as f:
        return [{k: (int(v) if k in COUNT_COLUMNS and v != "nan" else float(v)) for k, v in row.items()}
                for row in csv.DictReader(f)]


def save_policy(model, settings: dict, out: pathlib.Path) -> None:
    """Model (``ppo.zip``), normalisation (``vecnormalize.pkl``) and settings (``run.json``): what
    ``eval_ppo.py`` reads."""
    model.save(out / "ppo.zip")
    model.get_vec_normalize_env().save(str(out / "vecnormalize.pkl"))
    (out / "run.json").write_text(json.dumps(settings, indent=1) + "\n")


def save_run(model, curve: LearningCurve, out: pathlib.Path, title: str) -> None:
    """``save_policy`` and the curve of a run, for ``--resume``."""
    save_curve(curve.rows, out, title)
    save_policy(model, curve.settings, out)


#: Settings ``run.json`` records since a later version, with the value every earlier run used.
RECORDED_SINCE = {"learning_rate": 3e-4}


#: Settings of how a run started (``train``'s ``clone`` and ``policy_std``): recorded, not repeated by a resume.
START_SETTINGS = ("clone_expert", "policy_std")


def check_resume(folder: pathlib.Path, settings: dict) -> list[dict]:
    """The curve rows of the run saved in ``folder`` if its settings (``run.json``; a key it lacks
    reads as ``RECORDED_SINCE`` gives) are ``settings`` (the simulation device may differ); else
    ValueError naming each difference."""
    path = pathlib.Path(folder) / "run.json"
    if not path.is_file():
        raise FileNotFoundError(f"--resume {folder}: no run.json there (the settings save_run writes)")
    saved = {**RECORDED_SINCE, **json.loads(path.read_text())}
    settings = json.loads(json.dumps(settings))  # as saved: tuples become lists
    # the devices may differ; a resumed run is not started again (its start is in its weights)
    keys = [k for k in sorted(set(saved) | set(settings)) if k not in ("device", "shard_devices") + START_SETTINGS]
    differ = [f"{k}: saved {saved.get(k)!r}, given {settings.get(k)!r}"
              for k in keys if saved.get(k) != settings.get(k)]
    if differ:
        raise ValueError(f"--resume {folder}: the run was trained with other options ({'; '.join(differ)}); "
                         "pass the saved run's options")
    return read_curve(folder)


#: The policy's initial log std of a fresh run (and of an action component a ``--init-from`` policy lacks).
LOG_STD_INIT = -0.5


def run_settings(num_envs: int, n_steps: int, actions: str, gamma: float, gae_lambda: float, n_epochs: int,
                 learning_rate: float, seed: int, init_from=None, fixed_world_objects: bool = False,
                 stagger_episodes: bool = False, shard_devices: list[str] | None = None, **env_kwargs) -> dict:
    """A run's ``run.json``: its PPO and env options (``check_resume`` compares them; ``eval_ppo.py``
    and ``PPOPolicy`` rebuild the env from them)."""
    from defgrasp_env import PickupConfig

    settings = dict(num_envs=num_envs, n_steps=n_steps, actions=actions, gamma=gamma, gae_lambda=gae_lambda,
                    n_epochs=n_epochs, learning_rate=learning_rate, seed=seed, **env_kwargs)
    if init_from is not None:
        settings["init_from"] = str(init_from)
    # recorded only where on (the default since 2026-11-26): the run.json of a run without it (all
    # earlier runs) lacks the key, and eval_ppo reads a missing key as off
    settings.pop("edge_contact", None)
    if PickupConfig(**env_kwargs).edge_contact:
        settings["edge_contact"] = True
    if fixed_world_objects:  # only when set: the run.json of earlier runs lacks it
        settings["fixed_world_objects"] = True
    if stagger_episodes:  # the same
        settings["stagger_episodes"] = True
    if shard_devices is not None:  # the same (a run may resume on other devices: not compared)
        settings["shard_devices"] = list(shard_devices)
    return settings


def new_ppo(venv, n_steps: int, minibatches: int, n_epochs: int, learning_rate: float, gamma: float,
            gae_lambda: float, seed: int, torch_device: str = "cpu", verbose: int = 0):
    """A fresh SB3 PPO on ``venv`` with this script's settings (see the module docstring): a rollout
    of ``n_steps`` per world in ``minibatches`` minibatches (fewer where one would hold under 64
    samples), 3 x 256 networks, log std ``LOG_STD_INIT``."""
    from stable_baselines3 import PPO

    rollout = n_steps * venv.num_envs
    minibatches = max(1, min(minibatches, rollout // 64))
    return PPO("MultiInputPolicy", venv, n_steps=n_steps, batch_size=rollout // minibatches,
               n_epochs=n_epochs, learning_rate=learning_rate, gamma=gamma, gae_lambda=gae_lambda, clip_range=0.2,
               target_kl=0.1, max_grad_norm=0.5, vf_coef=0.5, ent_coef=0.0,
               policy_kwargs=dict(net_arch=[256, 256, 256], log_std_init=LOG_STD_INIT), seed=seed,
               device=torch_device, verbose=verbose)


@dataclass(frozen=True)
class ExpertClone:
    """``--clone-expert-steps``: a new run's policy starts as a clone of the scripted expert
    (``defgrasp_env.rl.expert_cloning``): ``steps`` vector steps of the expert with Gaussian action
    noise of std ``noise`` (one for all components or one per component of the action set) in the
    run's own env, then ``epochs`` passes of behaviour cloning (actor) and return regression (critic).
    The expert's jaw labels keep wider margins against a regression's errors: its slow close and
    squeeze lead the observed gap by ``close_lead`` periods (``ExpertConfig.delta_close_lead``; at
    1 the clone commanded about the gap it saw and stalled 2 mm above the stiff rope) and its hold
    stays ``grip_overtravel`` m inside the gap at first contact (``ExpertConfig.grip_overtravel``; at
    4 mm the clone's hold of the stiff cube slipped at the goal): the clone's jaw error is 0.078 RMS
    (3.3 mm; RESULTS.md, 2026-12-06), so a 3 mm lead still stalls some clones (the rope: 6 / 50)."""

    steps: int
    noise: float | tuple[float, ...] = 0.03  # the expert picked 10 / 10 so (0.1 on all: 2 / 10; RESULTS.md)
    epochs: int = 20
    close_lead: int = 3               # control periods
    grip_overtravel: float = 0.008    # m

    def __post_init__(self):
        if self.steps < 1 or self.epochs < 1 or not all(0.0 <= n < 1.0 for n in np.atleast_1d(self.noise)):
            raise ValueError(f"clone steps and epochs must be >= 1 and noise in [0, 1), got {self.steps}, "
                             f"{self.epochs}, {self.noise}")
        from defgrasp_env.policies import ExpertConfig

        try:  # validated as the expert's own settings
            ExpertConfig(**self.expert_options)
        except ValueError as e:
            raise ValueError(f"clone close_lead / grip_overtravel (--clone-close-lead, --clone-grip-overtravel): {e}") from e

    @property
    def expert_options(self) -> dict:
        """The ``ExpertConfig`` fields the cloned expert runs with."""
        return {"delta_close_lead": self.close_lead, "grip_overtravel": self.grip_overtravel}


def clone_options(args) -> ExpertClone:
    """``ExpertClone`` of the command line (``--clone-*``; the dataclass's defaults where not given)."""
    kw = {name: value for name, value in (("epochs", args.clone_epochs), ("close_lead", args.clone_close_lead),
                                           ("grip_overtravel", args.clone_grip_overtravel)) if value is not None}
    if args.clone_noise is not None:
        kw["noise"] = args.clone_noise[0] if len(args.clone_noise) == 1 else tuple(args.clone_noise)
    return ExpertClone(args.clone_expert_steps, **kw)


def clone_expert(model, venv, actions: str, clone: ExpertClone, seed: int) -> dict:
    """Fit ``model``'s policy to the scripted expert in ``venv`` (``clone``); returns the record
    ``run.json`` keeps: the options, the samples, the noisy expert's episodes that ended (the
    staggered first ones left out) and its successes among them, the largest expert action outside
    the action set, the times and the last epoch's losses (printed per epoch too)."""
    from defgrasp_env.rl.action_subset import ACTION_SETS
    from defgrasp_env.rl.expert_cloning import collect_expert_steps, fit_policy

    t0 = time.perf_counter()
    data = collect_expert_steps(venv, ACTION_SETS[actions], clone.steps, clone.noise,
                                np.random.default_rng([seed, 0xC10E]), clone.expert_options)
    t1 = time.perf_counter()
    history = fit_policy(model.policy, venv, data, model.gamma, epochs=clone.epochs, rng=np.random.default_rng(seed))
    t2 = time.perf_counter()
    for i, row in enumerate(history):
        print(f"clone epoch {i + 1}: " + ", ".join(f"{k} {v:.4f}" for k, v in row.items()), flush=True)
    record = dict(steps=clone.steps, noise=np.asarray(clone.noise).tolist(), epochs=clone.epochs,
                  expert_options=clone.expert_options, samples=data.num_samples,
                  expert_episodes=int(len(data.successes)), expert_successes=int(data.successes.sum()),
                  dropped_action_max=round(data.dropped_max, 4), collect_s=round(t1 - t0, 1), fit_s=round(t2 - t1, 1),
                  **{k: round(v, 5) for k, v in history[-1].items()})
    print("clone: " + json.dumps(record), flush=True)
    return record


def set_policy_std(policy, std: float) -> float:
    """Set the std of SB3 ``policy``'s Gaussian (its ``log_std``) to ``std`` on every component; returns it."""
    import torch

    if not 0.0 < std < 10.0:
        raise ValueError(f"policy std must be in (0, 10), got {std}")
    with torch.no_grad():
        policy.log_std.fill_(float(np.log(std)))
    return float(std)


def train(num_envs: int, timesteps: int, seed: int = 0, n_steps: int = 16, minibatches: int = 32,
          torch_device: str = "cpu", verbose: int = 0, max_seconds: float = float("inf"), actions: str = "full",
          gamma: float = 0.8, gae_lambda: float = 0.9, n_epochs: int = 8, learning_rate: float = 3e-4,
          resume: pathlib.Path | None = None, init_from: pathlib.Path | None = None,
          fixed_world_objects: bool = False, stagger_episodes: bool = False, best: BestPolicy | None = None,
          shard_devices: list[str] | None = None, clone: ExpertClone | None = None,
          policy_std: float | None = None, freeze_obs_normalisation: bool = False, **env_kwargs):
    """Train PPO for ``timesteps`` env steps or ``max_seconds`` of wall time, whichever comes first;
    returns (model, LearningCurve). A rollout of ``n_steps`` per world is learned from in
    ``n_epochs`` passes of ``minibatches`` minibatches (fewer where one would hold under 64 samples)
    at Adam's ``learning_rate``.
    ``resume``: a folder ``save_run`` wrote, with the same settings (``check_resume``); its model,
    normalisation statistics and curve go on, the env seeded with ``seed`` + the env steps so far.
    ``init_from``: a folder ``save_run`` wrote, whose policy weights and normalisation statistics
    start this new run (e.g. a GPU run's policy fine-tuned with fewer worlds or another reward); its
    settings may differ (another ``actions`` set too: ``transfer_policy``); the curve starts afresh.
    ``fixed_world_objects``: see ``make_vec_env``. ``stagger_episodes``: each world's first episode
    cut at a random step (``SB3VectorEnv(stagger_first_episodes=True)``). ``best``: keeps the policy of the best cohort rate.
    ``shard_devices``: see ``make_vec_env``. ``clone``: a new run (neither ``resume`` nor
    ``init_from``) starts from the scripted expert (``clone_expert``); its options and outcome go to
    the run's settings as ``clone_expert``. ``policy_std``: a new run's policy starts with this
    std on every action component (after ``init_from`` or ``clone``, which otherwise set it).
    ``freeze_obs_normalisation``: the observation statistics stay those the run starts with (after
    ``init_from`` / ``clone``; ``rl.normalisation``), for a fine-tune of a policy fitted under them;
    otherwise they are updated as the run goes (a frozen ``init_from`` run's thawed)."""
    from stable_baselines3 import PPO

    from defgrasp_env import PickupConfig
    from defgrasp_env.rl.normalisation import set_observation_statistics_frozen
    from defgrasp_env.rl.policy_transfer import transfer_policy

    settings = run_settings(num_envs=num_envs, n_steps=n_steps, actions=actions, gamma=gamma, gae_lambda=gae_lambda,
                            n_epochs=n_epochs, learning_rate=learning_rate, seed=seed, init_from=init_from,
                            fixed_world_objects=fixed_world_objects, stagger_episodes=stagger_episodes,
                            shard_devices=shard_devices, **env_kwargs)
    if freeze_obs_normalisation:  # only when set: the run.json of earlier runs lacks it
        settings["freeze_obs_normalisation"] = True
    if clone is not None and (resume is not None or init_from is not None):
        raise ValueError("a clone of the expert (--clone-expert-steps) starts a new run from random weights: "
                         "not with --resume or --init-from")
    if policy_std is not None and resume is not None:
        raise ValueError("--policy-std sets a new run's start: not with --resume (the run's std goes on)")
    config = PickupConfig(**env_kwargs)
    tolerance = config.success_tolerance
    episode_steps = config.max_episode_steps
    # successes that do not end episodes: the holding rate of world-steps HOLDING_SECONDS into their episode
    holding = None if config.terminate_on_success else int(round(HOLDING_SECONDS * config.control_hz))
    # drawn training goals: the episodes at the task's goal (the default config's, eval_ppo's) apart
    task_goal = PickupConfig().goal if any(config.goal_noise) else None
    if resume is not None:
        resume = pathlib.Path(resume)
        rows = check_resume(resume, settings)
        saved = json.loads((resume / "run.json").read_text())
        for key in START_SETTINGS:  # the run's start, kept in its record
            if key in saved:
                settings[key] = saved[key]
        env_seed = seed + (rows[-1]["env_steps"] if rows else 0)
        venv = make_vec_env(num_envs, env_seed, actions=actions, gamma=gamma,
                            fixed_world_objects=fixed_world_objects, stagger_episodes=stagger_episodes,
                            shard_devices=shard_devices, **env_kwargs)
        venv = load_normalisation(resume, venv)
        set_observation_statistics_frozen(venv, freeze_obs_normalisation)  # as saved (check_resume)
        model = PPO.load(resume / "ppo.zip", env=venv, device=torch_device)
        model.set_random_seed(env_seed)  # PPO.load re-seeds the env with the saved run's seed
        curve = LearningCurve(settings, env_seed, max_seconds, rows=rows, success_tolerance=tolerance,
                              episode_steps=episode_steps, best=best, task_goal=task_goal, holding_steps=holding)
        model.learn(timesteps, callback=curve, reset_num_timesteps=False)
        return model, curve
    venv = make_vec_env(num_envs, seed, actions=actions, gamma=gamma, fixed_world_objects=fixed_world_objects,
                        stagger_episodes=stagger_episodes, shard_devices=shard_devices, **env_kwargs)
    if init_from is not None:
        # the loaded statistics go on; the return normalisation uses this run's discount
        venv = load_normalisation(init_from, venv, gamma)
    model = new_ppo(venv, n_steps=n_steps, minibatches=minibatches, n_epochs=n_epochs, learning_rate=learning_rate,
                    gamma=gamma, gae_lambda=gae_lambda, seed=seed, torch_device=torch_device, verbose=verbose)
    if init_from is not None:
        trained = PPO.load(pathlib.Path(init_from) / "ppo.zip", device=torch_device)
        source_actions = json.loads((pathlib.Path(init_from) / "run.json").read_text()).get("actions", "full")
        model.policy.load_state_dict(transfer_policy(trained.policy.state_dict(), source_actions,
                                                     model.policy.state_dict(), actions, LOG_STD_INIT))
    if clone is not None:
        settings["clone_expert"] = clone_expert(model, venv, actions, clone, seed)
    if policy_std is not None:
        settings["policy_std"] = set_policy_std(model.policy, policy_std)
    set_observation_statistics_frozen(venv, freeze_obs_normalisation)
    curve = LearningCurve(settings, seed, max_seconds, success_tolerance=tolerance, episode_steps=episode_steps,
                          best=best, task_goal=task_goal, holding_steps=holding)
    model.learn(timesteps, callback=curve)
    return model, curve


def save_curve(rows: list[dict], out: pathlib.Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    with open(out / "curve.csv", "w", newline="") as f:
        fields = list(dict.fromkeys(k for r in rows for k in r))  # a resumed run's older rows may lack columns
        w = csv.DictWriter(f, fieldnames=fields, restval="nan")
        w.writeheader()
        w.writerows(rows)
    steps = [r["env_steps"] for r in rows]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.4))
    for ax, x, label in ((axes[0], steps, "env steps"), (axes[1], [r["wall_s"] / 60 for r in rows], "wall time (min)")):
        ax.plot(x, [r["success_rate"] for r in rows], "o-", ms=3, alpha=0.5,
                label="success rate (episodes ended in the rollout: early successes over-represented)")
        ax.plot(x, [r.get("cohort_success_rate", float("nan")) for r in rows], "D-", ms=3,
                label="success rate (episodes begun one time limit earlier: unbiased)")
        if any("task_goal_cohort_success_rate" in r for r in rows):  # drawn training goals
            ax.plot(x, [r.get("task_goal_cohort_success_rate", float("nan")) for r in rows], "*-", ms=4,
                    label="success rate (the cohort's episodes with a goal at the task's)")
        if any("holding_rate" in r for r in rows):  # successes that do not end episodes
            ax.plot(x, [r.get("holding_rate", float("nan")) for r in rows], "P-", ms=4,
                    label=f"held at the goal (world-steps {HOLDING_SECONDS:g} s or more into their episode)")
        ax.plot(x, [r["grasped_fraction"] for r in rows], "s-", ms=3, label="grasped fraction (world-steps)")
        ax.plot(x, [r.get("at_goal_fraction", float("nan")) for r in rows], "^-", ms=3,
                label="grasped at the goal (world-steps)")
        ax.set_xlabel(label)
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel("fraction, per PPO rollout")
        ax.grid(alpha=0.3)
    fig.legend(*axes[0].get_legend_handles_labels(), loc="lower center", ncol=2, fontsize=7)  # below, off the data
    fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0.0, 0.1, 1.0, 1.0))
    fig.savefig(out / "curve.png", dpi=110)


def parse_object(text: str) -> str | tuple[str, ...]:
    """``--object``: one name (or 'random'), or several separated by commas (a tuple)."""
    names = tuple(n.strip() for n in text.split(","))
    return names if len(names) > 1 else names[0]


def main(argv=None) -> int:
    from defgrasp_env.rl.action_subset import ACTION_SETS

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--num-envs", type=int, default=16)
    ap.add_argument("--timesteps", type=int, default=100_000, help="env steps (all worlds together)")
    ap.add_argument("--n-steps", type=int, default=16, help="PPO rollout length per world")
    ap.add_argument("--actions", choices=sorted(ACTION_SETS), default="full",
                    help="what the policy controls: all 7 delta actions, wrist position and jaw, or wrist "
                         "position, its turn about the vertical and jaw")
    ap.add_argument("--gamma", type=float, default=0.8)
    ap.add_argument("--learning-rate", type=float, default=3e-4, help="Adam's step size (a fine-tune may want less)")
    ap.add_argument("--object", default="cuboid",
                    help="an object name, 'random' (the five), or names separated by commas (drawn from)")
    ap.add_argument("--fixed-world-objects", action="store_true",
                    help="world i holds the i-th object (mod their count) in every episode: no model rebuild "
                         "at autoresets (the vector env's world_objects)")
    ap.add_argument("--youngs-modulus", type=float, nargs="+", default=[1e6],
                    help="Pa; several values: each episode draws one (PickupConfig.youngs_modulus as a tuple)")
    ap.add_argument("--episode-seconds", type=float, default=15.0)
    ap.add_argument("--edge-contact", action=argparse.BooleanOptionalAction, default=True,
                    help="hold the pads' box edges and corners out of the object (PickupConfig.edge_contact, the "
                         "default; --no-edge-contact: node-vs-box contact alone, as runs before 2026-11-26)")
    ap.add_argument("--stagger-episodes", action="store_true",
                    help="cut each world's first episode at a random step, so that the worlds run their "
                         "episodes out of phase (SB3VectorEnv(stagger_first_episodes=True)); for "
                         "--no-terminate-on-success, whose episodes otherwise all end together")
    ap.add_argument("--terminate-on-success", action=argparse.BooleanOptionalAction, default=True,
                    help="--no-terminate-on-success: a success does not end a training episode, its bonus "
                         "repeats while the object stays at the goal (PickupConfig.terminate_on_success; "
                         "eval_ppo.py evaluates with the env's default, terminating)")
    ap.add_argument("--goal", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                    help="train with this goal (m, world; default the env's 0 0.6 0)")
    ap.add_argument("--goal-noise", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                    help="draw each training episode's goal within --goal +- this (m per axis; PickupConfig."
                         "goal_noise): a curriculum of goals from near the ground up, e.g. --goal 0 0.35 0 "
                         "--goal-noise 0 0.3 0. eval_ppo.py evaluates at the env's task goal")
    ap.add_argument("--device", default="cpu",
                    help="simulation device (cpu, cuda:0), or several separated by commas: the worlds split over "
                         "one vector env per entry, stepped in threads (cpu,cpu: two CPU cores; cuda:0,cuda:1: two "
                         "GPUs; defgrasp_env.make_sharded_vec)")
    ap.add_argument("--torch-device", default="cpu", help="PPO network device")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--minutes", type=float, default=float("inf"), help="stop after this wall time (min)")
    ap.add_argument("--out", default=str(ROOT / "datasets" / "output" / "ppo"))
    ap.add_argument("--resume", default=None, help="folder of an earlier run (ppo.zip, vecnormalize.pkl, curve.csv)")
    ap.add_argument("--init-from", default=None,
                    help="folder of an earlier run whose policy and normalisation start a new run (other options "
                         "allowed); a run started so is resumed with the same --init-from")
    ap.add_argument("--clone-expert-steps", type=int, default=0,
                    help="start the new run's policy as a clone of the scripted expert: this many vector steps of "
                         "the expert with action noise in the run's env, then behaviour cloning (0: off; "
                         "--timesteps 0 saves the clone alone)")
    ap.add_argument("--clone-noise", type=float, nargs="+", default=None,
                    help="std of the expert's action noise while cloning: one for all components (default 0.03), "
                         "or one per component of --actions (e.g. 0.1 0.1 0.1 0.1 0 for position-yaw-jaw: no jaw "
                         "noise, as the shipped clone)")
    ap.add_argument("--clone-epochs", type=int, default=None, help="passes over the expert's steps (default 20)")
    ap.add_argument("--clone-close-lead", type=int, default=None,
                    help="control periods by which the cloned expert's closing jaw command leads the gap (default 3)")
    ap.add_argument("--clone-grip-overtravel", type=float, default=None,
                    help="m the cloned expert's hold command stays inside the gap at first contact (default 0.008)")
    ap.add_argument("--policy-std", type=float, default=None,
                    help="a new run's policy starts with this std on every action component (default: 0.61 for a "
                         "fresh policy, --init-from's, or the clone's noise)")
    ap.add_argument("--freeze-obs-normalisation", action="store_true",
                    help="keep the observation normalisation statistics the run starts with (--init-from's or the "
                         "clone's): a policy fitted under them reads other inputs for the same state once they drift "
                         "(PPO from the expert clone then held every object 0.1 m below the goal, RESULTS.md)")
    ap.add_argument("--best-min-episodes", type=int, default=256,
                    help="keep the policy of the best cohort success rate over at least this many episodes in "
                         "--out/best (0: do not keep it)")
    args = ap.parse_args(argv)
    clone_flags = {"--clone-noise": args.clone_noise, "--clone-epochs": args.clone_epochs,
                   "--clone-close-lead": args.clone_close_lead, "--clone-grip-overtravel": args.clone_grip_overtravel}
    if not args.clone_expert_steps and any(v is not None for v in clone_flags.values()):
        ap.error(f"{[k for k, v in clone_flags.items() if v is not None]} need --clone-expert-steps")
    devices = [d.strip() for d in args.device.split(",")]
    if len(devices) > args.num_envs or not all(devices):
        ap.error(f"--device must name 1 to --num-envs ({args.num_envs}) devices separated by commas, got {args.device!r}")
    t0 = time.perf_counter()
    out = pathlib.Path(args.out)
    resumed = args.resume is not None and pathlib.Path(args.resume).resolve() == out.resolve()
    # a run on drawn goals keeps the policy best at the task's goal (the pooled rate of its episodes there)
    ranking = TASK_GOAL_RANKING if args.goal_noise is not None and any(args.goal_noise) else ()
    best = BestPolicy(out / "best", args.best_min_episodes, resumed, *ranking) if args.best_min_episodes > 0 else None
    # recorded in run.json only where given (the settings of earlier runs lack them)
    goals = {k: tuple(v) for k, v in (("goal", args.goal), ("goal_noise", args.goal_noise)) if v is not None}
    if not args.terminate_on_success:  # likewise recorded only where off
        goals["terminate_on_success"] = False
    # one value as before (run.json: a number), several drawn per episode (a list)
    moduli = args.youngs_modulus[0] if len(args.youngs_modulus) == 1 else tuple(args.youngs_modulus)
    model, curve = train(args.num_envs, args.timesteps, args.seed, args.n_steps, torch_device=args.torch_device,
                         max_seconds=60.0 * args.minutes, actions=args.actions, gamma=args.gamma,
                         learning_rate=args.learning_rate, resume=args.resume,
                         init_from=args.init_from, fixed_world_objects=args.fixed_world_objects,
                         stagger_episodes=args.stagger_episodes,
                         object=parse_object(args.object), youngs_modulus=moduli,
                         episode_seconds=args.episode_seconds, edge_contact=args.edge_contact, device=devices[0],
                         shard_devices=devices if len(devices) > 1 else None, best=best,
                         clone=clone_options(args) if args.clone_expert_steps else None, policy_std=args.policy_std,
                         freeze_obs_normalisation=args.freeze_obs_normalisation, **goals)
    wall = curve.rows[-1]["wall_s"] if curve.rows else time.perf_counter() - t0  # resumed runs included
    title = (f"PPO (SB3) on DeformablePickup-v0 vector env: {args.object}, E = {', '.join(f'{e:g}' for e in args.youngs_modulus)} Pa, "
             f"{args.num_envs} worlds on {args.device}, actions {args.actions}; {model.num_timesteps} env steps "
             f"in {wall / 60:.1f} min")
    save_run(model, curve, out, title)
    print(title)
    print("| env steps | wall (s) | episodes ended | success rate (ended) | success rate (cohort) [episodes] | "
          "mean return | grasped fraction | at goal | step ms p50 / p95 | slowest world Newton / CG per step |\n"
          "|---|---|---|---|---|---|---|---|---|---|")
    for r in curve.rows:
        print(f"| {r['env_steps']} | {r['wall_s']} | {r['episodes']} | {r['success_rate']:.2f} | "
              f"{r.get('cohort_success_rate', float('nan')):.2f} [{r.get('cohort_episodes', 'n/a')}] | "
              f"{r['mean_return']:.1f} | {r['grasped_fraction']:.3f} | {r.get('at_goal_fraction', float('nan')):.3f} | "
              f"{r.get('step_ms_p50', float('nan')):.0f} / "
              f"{r.get('step_ms_p95', float('nan')):.0f} | {r.get('slowest_newton', float('nan')):.0f} / "
              f"{r.get('slowest_cg', float('nan')):.0f} |")
    print(f"env steps/s: {model.num_timesteps / wall:.1f}; curve: {out / 'curve.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
