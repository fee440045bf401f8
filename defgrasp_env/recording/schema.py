"""The episode file schema (the paper's Table 1 plus replay data): the one source of truth.

One HDF5 file holds one episode. Every dataset carries ``units`` and ``description`` attributes;
``datasets/README.md`` holds the table rendered by :func:`schema_markdown` (a test keeps them equal).

Symbolic dimensions: ``T`` control steps of the episode, ``N1`` surface triangles, ``N2`` tetrahedra,
``N3`` nodes, ``A`` action size, ``H``/``W`` camera image size, ``O``/``S`` observation sizes.
Row ``k`` of a ``steps/`` dataset is the state right after action ``k`` (time ``(k+1) dt``);
row ``k`` of an ``observations/`` dataset is what the policy saw before action ``k`` (row 0 = reset,
row ``T`` = after the last action), as in Minari.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Value of the root attribute ``format``; files without it are not defgrasp episodes.
FORMAT = "defgrasp.episode"
#: Bumped on any incompatible change of the layout below.
SCHEMA_VERSION = 1
#: File suffix of episode files.
SUFFIX = ".h5"


@dataclass(frozen=True)
class Field:
    """One dataset of an episode file."""

    dtype: str                       # numpy dtype name
    shape: tuple[str | int, ...]     # symbolic shape ("T", "N3", 3, ...); () for a scalar
    units: str                       # UDUNITS-style; "1" = dimensionless, "mixed" = see ``names`` attr
    description: str
    paper: bool = False              # listed in the paper's Table 1
    required: bool = True


FIELDS: dict[str, Field] = {
    # -- General description (Table 1, upper half) ---------------------------------------------
    "object/initial_position": Field("float64", (3,), "m", "object frame origin in the world at reset", True),
    "object/initial_quaternion": Field("float64", (4,), "1", "object frame orientation at reset, xyzw", True),
    "object/density": Field("float64", (), "kg/m^3", "mass density", True),
    "object/youngs_modulus": Field("float64", (), "Pa", "elastic (Young's) modulus E", True),
    "object/poisson_ratio": Field("float64", (), "1", "Poisson ratio", True),
    "object/triangles": Field("int32", ("N1", 3), "1", "surface triangles, node indices (0-based)", True),
    "object/tetrahedra": Field("int32", ("N2", 4), "1", "tetrahedra, node indices (0-based)", True),
    "object/rest_nodes": Field("float64", ("N3", 3), "m", "mesh nodes in the object frame (rest shape)"),
    "task/goal": Field("float64", (3,), "m", "the episode's goal for the feature point, world frame "
                       "(drawn per episode with the config's goal_noise)", required=False),
    # -- Per time step (Table 1, lower half) -----------------------------------------------------
    "steps/time": Field("float64", ("T",), "s", "simulation time at the end of the step", True),
    "steps/node_positions": Field("float32", ("T", "N3", 3), "m", "node positions, world frame", True),
    "steps/node_forces": Field("float32", ("T", "N3", 3), "N", "force on each node: elastic + contact", True),
    "steps/von_mises": Field("float32", ("T", "N2"), "Pa", "von Mises stress of each tetrahedron", True),
    "steps/mean_von_mises": Field("float32", ("T",), "Pa", "rest-volume-weighted mean von Mises stress", True),
    "steps/wrist_position": Field("float64", ("T", 3), "m", "wrist (flange) position, world frame", True),
    "steps/wrist_orientation": Field("float64", ("T", 4), "1", "wrist (flange) orientation, xyzw", True),
    "steps/jaw_length": Field("float64", ("T",), "m", "gripper jaw length D (gap between pad faces)", True),
    "steps/left_tip_normal_force": Field("float64", ("T",), "N", "normal force on the left gripper tip", True),
    "steps/right_tip_normal_force": Field("float64", ("T",), "N", "normal force on the right gripper tip", True),
    # -- Beyond the paper: full state and the transition -----------------------------------------
    "steps/node_velocities": Field("float32", ("T", "N3", 3), "m/s", "node velocities, world frame"),
    "steps/contact_forces": Field("float32", ("T", "N3", 3), "N", "contact part of node_forces (ground + pads)"),
    "steps/action": Field("float64", ("T", "A"), "mixed", "action passed to step() (before clipping)"),
    "steps/reward": Field("float64", ("T",), "1", "reward returned by step()"),
    "steps/terminated": Field("bool", ("T",), "1", "terminated flag returned by step()"),
    "steps/truncated": Field("bool", ("T",), "1", "truncated flag returned by step()"),
    "steps/is_success": Field("bool", ("T",), "1", "info['is_success']"),
    "observations/agent_pos": Field("float32", ("T+1", "O"), "mixed", "observation 'agent_pos'", required=False),
    "observations/environment_state": Field("float32", ("T+1", "S"), "mixed", "observation 'environment_state'",
                                            required=False),
    "observations/pixels": Field("uint8", ("T+1", "H", "W", 3), "1", "camera image (RGB)",
                                 required=False),
}

#: ``info/<key>`` datasets: one per scalar entry of the step's ``info`` dict, shape (T,).
INFO_GROUP = "info"

#: Root attributes: name -> (python type, description).
ROOT_ATTRS: dict[str, tuple[type, str]] = {
    "format": (str, f"always {FORMAT!r}"),
    "schema_version": (int, f"layout version ({SCHEMA_VERSION})"),
    "env_id": (str, "Gymnasium id of the recorded env"),
    "config_json": (str, "the env's PickupConfig as JSON (every field, nested dataclasses as objects)"),
    "replay_json": (str, "JSON: seed, rng_state, options, scene_origin, max_episode_steps - what replay needs"),
    "versions_json": (str, "JSON: versions of defgrasp, python, numpy, warp, gymnasium, h5py"),
    "object_name": (str, "object shape name or mesh path"),
    "control_hz": (float, "control rate, Hz (one row per control step)"),
    "dt": (float, "control period, s"),
    "num_steps": (int, "T"),
    "episode_index": (int, "the {index} of the file name (continues the numbering of the folder)"),
    "world": (int, "world of the env that ran the episode: 0 for a single env, 0..N-1 for the vector env"),
    "terminated": (bool, "the last step terminated the episode"),
    "truncated": (bool, "the last step truncated the episode"),
    "is_success": (bool, "info['is_success'] of the last step"),
    "end_reason": (str, "'terminated', 'truncated', 'reset' or 'close' (what ended the recording)"),
    "created_utc": (str, "ISO 8601 time the file was written"),
}
#: Root attributes a file may lack (files written before they existed, or a recorder not told): name ->
#: (python type, description); checked when present.
OPTIONAL_ROOT_ATTRS: dict[str, tuple[type, str]] = {
    "policy": (str, "what chose the actions: `defgrasp-generate --policy` (module:attribute or 'random'), "
                    "'teleop' for the collection app, or what a recorder's `policy=` was given"),
}

def shape_text(shape: tuple[str | int, ...]) -> str:
    return "scalar" if shape == () else "[" + ", ".join(str(d) for d in shape) + "]"


def schema_markdown() -> str:
    """The Markdown table of the schema (what datasets/README.md must contain verbatim)."""
    lines = ["| Dataset | Type | Shape | Units | Table 1 | Description |",
             "|---|---|---|---|---|---|"]
    for path, f in FIELDS.items():
        req = "" if f.required else " (optional)"
        lines.append(f"| `{path}` | {f.dtype} | {shape_text(f.shape)} | {f.units} | "
                     f"{'yes' if f.paper else ''} | {f.description}{req} |")
    lines.append(f"| `{INFO_GROUP}/<key>` | float64 / int64 / bool | [T] | - |  | "
                 "every scalar entry of the step's info dict |")
    lines += ["", "| Root attribute | Type | Description |", "|---|---|---|"]
    for name, (typ, desc) in ROOT_ATTRS.items():
        lines.append(f"| `{name}` | {typ.__name__} | {desc} |")
    for name, (typ, desc) in OPTIONAL_ROOT_ATTRS.items():
        lines.append(f"| `{name}` | {typ.__name__} | {desc} (optional) |")
    return "\n".join(lines) + "\n"
