"""``defgrasp-dataset``: validate, convert, plot and replay recorded episodes.

    defgrasp-dataset validate PATH [PATH ...] # files or folders; exit 1 if any file is invalid
    defgrasp-dataset to-lerobot SRC DST       # new LeRobot v3.0 dataset at DST
    defgrasp-dataset plot EPISODE [-o PNG]    # the paper's Fig. 5 panels
    defgrasp-dataset replay EPISODE           # re-simulate; exit 1 unless every step is bit-exact
    defgrasp-dataset view EPISODE [--port N]  # 3D playback in the browser, with a timeline ([viewer] extra)
    defgrasp-dataset schema                   # the schema table (Markdown)
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys

_CACHE_VARS = {"WARP_CACHE_PATH": "warp", "HF_HOME": "hf", "HF_LEROBOT_HOME": "lerobot", "MPLCONFIGDIR": "mpl"}


def default_caches() -> None:
    """Send library caches to ``./.cache`` unless the user chose places (never to ``~``)."""
    root = pathlib.Path(os.environ.get("DEFGRASP_CACHE", pathlib.Path.cwd() / ".cache"))
    for var, sub in _CACHE_VARS.items():
        os.environ.setdefault(var, str(root / sub))


def _validate(args) -> int:
    from .validate import validate_path

    report = validate_path(*args.paths)
    print(report.text())
    return 0 if report.ok else 1


def _to_lerobot(args) -> int:
    from .lerobot_export import to_lerobot

    ds = to_lerobot(args.src, args.dst, repo_id=args.repo_id, task=args.task, use_videos=args.videos,
                    progress=True, state_fields=args.state_fields)
    print(f"wrote LeRobot dataset {ds.repo_id} to {args.dst}: {ds.meta.total_episodes} episode(s), "
          f"{ds.meta.total_frames} frame(s) at {ds.meta.fps} fps")
    return 0


def _plot(args) -> int:
    from .plot import plot_episode

    print(f"wrote {plot_episode(args.episode, args.output)}")
    return 0


def _replay(args) -> int:
    from .replay import replay_episode

    result = replay_episode(args.episode, device=args.device)
    print(result.text())
    return 0 if result.bit_exact else 1


def _view(args) -> int:
    from ..viewer.playback import view_episode

    view_episode(args.episode, host=args.host, port=args.port)
    return 0


def _schema(args) -> int:
    from .schema import schema_markdown

    print(schema_markdown(), end="")
    return 0


def _validate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("paths", nargs="+", metavar="PATH", help="episode file or folder of episode files")


def _to_lerobot_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("src", help="episode file or folder")
    p.add_argument("dst", help="new LeRobot dataset folder (must not exist)")
    p.add_argument("--repo-id", default=None, help="LeRobot repo id (default defgrasp/<dst name>)")
    p.add_argument("--task", default=None, help="task string (default: per episode, from object and E)")
    p.add_argument("--videos", action="store_true", help="store camera frames as MP4 instead of PNG")
    p.add_argument("--state-fields", nargs="+", default=None, metavar="FIELD",
                   help="the agent_pos fields observation.state keeps (default all: wrist_position wrist_quat "
                        "jaw_gap tip_normal_force); evaluate with --env.state_fields='[...]' alike")


def _plot_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("episode")
    p.add_argument("-o", "--output", default=None, help="PNG path (default: episode path with .png)")


def _replay_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("episode")
    p.add_argument("--device", default=None, help="Warp device (default: the recorded one)")


def _view_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("episode")
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1; 0.0.0.0: any)")
    p.add_argument("--port", type=int, default=8080, help="port to serve on (default 8080; 0: any free)")


def _no_args(p: argparse.ArgumentParser) -> None:
    pass


#: The subcommands: name -> (help, add_arguments(parser), run(args) -> exit code). Add a row to extend.
COMMANDS = {
    "validate": ("check episode files against the schema", _validate_args, _validate),
    "to-lerobot": ("convert episodes to a LeRobot dataset", _to_lerobot_args, _to_lerobot),
    "plot": ("draw the paper's Fig. 5 panels of one episode", _plot_args, _plot),
    "replay": ("re-simulate an episode and compare node positions bit for bit", _replay_args, _replay),
    "view": ("replay an episode in a 3D browser view with a timeline", _view_args, _view),
    "schema": ("print the episode schema table", _no_args, _schema),
}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="defgrasp-dataset", description=__doc__.split("\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    for name, (help_text, add_arguments, run) in COMMANDS.items():
        c = sub.add_parser(name, help=help_text)
        add_arguments(c)
        c.set_defaults(func=run)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    default_caches()
    try:
        return args.func(args)
    except (OSError, ValueError, TypeError, KeyError, ImportError) as exc:
        message = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        print(f"defgrasp-dataset {args.command}: error: {' '.join(str(message).split())}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
