"""Success table of a trained LeRobot policy, by ``lerobot-eval``, in the layout of the paper's Table 2.

Each (object, E) cell is one run of LeRobot's own ``lerobot-eval`` entry point (``eval_main``, called
in this process with the cell's command line so that Warp's kernels load once):

    lerobot-eval --env.type=defgrasp --env.object=OBJ --env.youngs_modulus=E \\
        --policy.path=CKPT --policy.device=cpu --eval.n_episodes=N --eval.batch_size=B \\
        --seed=SEED --output_dir=OUT/OBJ_E

Success is LeRobot's ``pc_success`` (``info["is_success"]`` at the episode's end) from each cell's
``eval_info.json``. Printed: the table with the scripted expert's rate (``success_table.py``, the
same env defaults) and the paper's human rate beside each cell, plus timing (also written to
``OUT/report.md``); ``OUT/episodes.json`` keeps every found cell's episodes in order (success, reward
sum and maximum, the folders they came from and each folder's ``lerobot-eval`` command line, which
the cell run keeps in the folder as ``lerobot_eval_command.json``; ``seed`` and ``lerobot_eval_args``
there are this call's, which ran the cells in ``cells_run``, None and [] for a table-only call).
``--append`` adds the report to ``benchmarks/RESULTS.md`` with the machine.

    python benchmarks/eval_lerobot_policy.py CKPT --episodes 5 --out datasets/output/eval_act
    python benchmarks/eval_lerobot_policy.py CKPT --objects torus --moduli 1e4 --policy.n_action_steps=1

Arguments this script does not know (``--env.*``, ``--policy.*``, ``--eval.*``) go to ``lerobot-eval``.
A policy trained on a dataset exported with ``--state-fields`` gets ``--env.state_fields`` of that
dataset added when its ``train_config.json`` leads to the dataset (``training_state_fields``).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from machine import append_results, git_state, host  # noqa: E402
from success_table import MODULI, OBJECTS, human_rate, modulus_label  # noqa: E402

#: The scripted expert's rate in every cell (benchmarks/RESULTS.md, success_table.py: 400/400).
EXPERT_RATE = 1.0


#: Each cell folder's record of the ``lerobot-eval`` command line that filled it (a JSON list).
COMMAND_FILE = "lerobot_eval_command.json"


def cell_name(obj: str, e: float) -> str:
    return f"{obj}_E{e:.0e}"


def eval_cell(ckpt: str, obj: str, e: float, episodes: int, batch: int, seed: int, out: pathlib.Path,
              extra: list[str]) -> dict:
    """Run ``lerobot-eval`` for one cell; returns its ``eval_info.json`` overall block."""
    from lerobot.scripts.lerobot_eval import eval_main

    cell_dir = out / cell_name(obj, e)
    argv = ["lerobot-eval", "--env.type=defgrasp", f"--env.object={obj}", f"--env.youngs_modulus={e}",
            f"--policy.path={ckpt}", "--policy.device=cpu", f"--eval.n_episodes={episodes}",
            f"--eval.batch_size={batch}", "--eval.use_async_envs=false", f"--seed={seed}",
            f"--output_dir={cell_dir}", *extra]
    print(" ".join(argv), flush=True)
    saved, sys.argv = sys.argv, argv
    try:
        eval_main()
    finally:
        sys.argv = saved
    (cell_dir / COMMAND_FILE).write_text(json.dumps(argv) + "\n")
    return json.loads((cell_dir / "eval_info.json").read_text())["overall"]


def pool_cell(dirs: list[pathlib.Path]) -> dict | None:
    """Success rate, episode count and time of one cell over the ``eval_info.json`` files in ``dirs``,
    and under ``"episodes"`` its episodes in order (``successes``, ``sum_rewards``, ``max_rewards``
    lists, the ``folders`` they were read from and each folder's ``lerobot-eval`` command line,
    ``commands``: None for a folder without its ``COMMAND_FILE``)."""
    found = [d for d in dirs if (d / "eval_info.json").is_file()]
    infos = [json.loads((d / "eval_info.json").read_text()) for d in found]
    if not infos:
        return None

    def per_episode(key: str) -> list:
        """LeRobot's per-episode metric ``key`` over all the cell's files, in order."""
        return [x for i in infos for task in i["per_task"] for x in task["metrics"][key]]

    successes = per_episode("successes")
    return {"pc_success": 100.0 * sum(successes) / len(successes), "n_episodes": len(successes),
            "successes": sum(successes), "eval_s": sum(i["overall"]["eval_s"] for i in infos),
            "episodes": {"successes": successes, "sum_rewards": per_episode("sum_rewards"),
                         "max_rewards": per_episode("max_rewards"), "folders": [str(d) for d in found],
                         "commands": [json.loads((d / COMMAND_FILE).read_text()) if (d / COMMAND_FILE).is_file()
                                      else None for d in found]}}


def format_report(cells: dict, wall: float, ckpt: str, train_note: str) -> str:
    counts = sorted({c["n_episodes"] for c in cells.values()})
    per_cell = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
    lines = [f"Policy `{ckpt}` ({train_note}); {per_cell} episodes per cell through `lerobot-eval`; "
             f"cell = learned (scripted expert / paper's human; n/a = not legible).", "",
             "| Young's modulus | " + " | ".join(o.capitalize() for o in OBJECTS) + " | Net |",
             "|---" * (len(OBJECTS) + 2) + "|"]
    for e in MODULI:
        rates = [cells[(o, e)]["pc_success"] / 100 for o in OBJECTS]
        row = [f"{r:.2f} [{cells[(o, e)]['successes']}/{cells[(o, e)]['n_episodes']}] "
               f"({EXPERT_RATE:.2f} / {human_rate(e, o)})" for r, o in zip(rates, OBJECTS)]
        lines.append(f"| {modulus_label(e)} | " + " | ".join(row)
                     + f" | **{sum(rates) / len(rates):.2f}** ({EXPERT_RATE:.2f} / {human_rate(e, 'net')}) |")
    cols = [sum(cells[(o, e)]["pc_success"] for e in MODULI) / 100 / len(MODULI) for o in OBJECTS]
    net = sum(cols) / len(cols)
    lines.append("| Net | " + " | ".join(f"{c:.2f} ({EXPERT_RATE:.2f} / {human_rate('net', o)})"
                                         for c, o in zip(cols, OBJECTS))
                 + f" | **{net:.2f}** ({EXPERT_RATE:.2f} / {human_rate('net', 'net')}) |")
    n = sum(c["n_episodes"] for c in cells.values())
    k = sum(c["successes"] for c in cells.values())
    lines += ["", f"{n} episodes, {k} successes; net success (mean of the cells) {net:.3f}; evaluation time {wall / 60:.1f} min "
              f"(sum over cells; mean {wall / max(n, 1):.1f} s per episode, video rendering included)."]
    return "\n".join(lines)


def with_state_fields(ckpt: str, extra: list[str]) -> list[str]:
    """``extra`` plus ``--env.state_fields=[...]`` of the checkpoint's training dataset when it holds
    a subset of ``agent_pos`` and ``extra`` does not set it (lerobot-eval would feed the policy the
    whole ``agent_pos`` and fail on the size)."""
    from defgrasp_env.layout import AGENT_POS
    from defgrasp_env.lerobot_policy import training_state_fields

    fields = training_state_fields(ckpt)
    if fields is None or len(fields) == len(AGENT_POS.fields) or any(a.startswith("--env.state_fields") for a in extra):
        return extra
    print(f"the policy was trained on observation.state = {fields}: adding --env.state_fields", flush=True)
    return [*extra, f"--env.state_fields=[{','.join(fields)}]"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", help="pretrained_model folder written by lerobot-train")
    ap.add_argument("--episodes", type=int, default=5, help="episodes per (object, E) cell (0: table only)")
    ap.add_argument("--batch-size", type=int, default=1, help="lerobot-eval --eval.batch_size")
    ap.add_argument("--seed", type=int, default=100_000, help="lerobot-eval --seed of every cell")
    ap.add_argument("--objects", default=",".join(OBJECTS))
    ap.add_argument("--moduli", default=",".join(f"{e:g}" for e in MODULI))
    ap.add_argument("--out", default=str(ROOT / "datasets" / "output" / "eval_lerobot"))
    ap.add_argument("--train-note", default="", help="training summary for the report (steps, time, machine)")
    ap.add_argument("--pool", nargs="*", default=[], help="further --out folders whose episodes join the table")
    ap.add_argument("--append", action="store_true", help="append the report to benchmarks/RESULTS.md")
    args, extra = ap.parse_known_args(argv)  # the rest goes to lerobot-eval (e.g. --env.episode_seconds=5)
    if any(not a.startswith("--") for a in extra):
        ap.error(f"unrecognized arguments: {extra}")
    from lerobot.utils.import_utils import register_third_party_plugins

    logging.basicConfig(level=logging.WARNING)
    import defgrasp_env.lerobot_env  # noqa: F401  (registers --env.type=defgrasp without the plugin install)

    register_third_party_plugins()
    extra = with_state_fields(args.checkpoint, extra)
    objects = args.objects.split(",")
    moduli = [float(x) for x in args.moduli.split(",")]
    out = pathlib.Path(args.out)
    ran = []
    for obj in objects if args.episodes > 0 else []:
        for e in moduli:
            t = time.perf_counter()
            overall = eval_cell(args.checkpoint, obj, e, args.episodes, args.batch_size, args.seed, out, extra)
            ran.append((obj, e))
            print(f"{obj:9s} E={e:.0e}: success {overall['pc_success']:.0f} % "
                  f"({time.perf_counter() - t:.0f} s)", flush=True)
    # the table pools every cell's episodes found in --out and the --pool folders (parallel runs over
    # other objects, or earlier passes with other seeds)
    pooled = {cell: pool_cell([d / cell_name(*cell) for d in [out, *map(pathlib.Path, args.pool)]])
              for cell in ((o, e) for o in OBJECTS for e in MODULI)}
    cells = {cell: c for cell, c in pooled.items() if c is not None}
    out.mkdir(parents=True, exist_ok=True)
    (out / "episodes.json").write_text(json.dumps(
        {"checkpoint": args.checkpoint, "cells_run": [cell_name(*c) for c in ran],
         "seed": args.seed if ran else None, "lerobot_eval_args": extra if ran else [],
         "cells": {cell_name(*cell): c["episodes"] for cell, c in cells.items()}},
        indent=1) + "\n")
    if len(cells) < len(OBJECTS) * len(MODULI):
        print(f"{len(cells)} of {len(OBJECTS) * len(MODULI)} cells found: no table yet")
        return 0
    wall = sum(c["eval_s"] for c in cells.values())
    report = format_report(cells, wall, args.checkpoint, args.train_note)
    print(report)
    (out / "report.md").write_text(report + "\n")
    if args.append:
        stamp = time.strftime("%Y-%m-%dT%H:%M:%S")
        append_results(f"## Learned policy (eval_lerobot_policy.py), {stamp}\n\nMachine: {host()}; "
                       f"{git_state()}.\n{report}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
