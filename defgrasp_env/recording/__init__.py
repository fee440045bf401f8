"""Recording of DeformablePickup episodes to HDF5 (the paper's Table 1 schema) and dataset tools.

* :class:`HDF5Recorder` - Gymnasium wrapper writing one crash-safe HDF5 file per episode.
* :class:`VectorHDF5Recorder` - the same for every world of the native vector env (files replay
  bit-exactly in a single env).
* :class:`EpisodeWriter` - the one writer both use: open episodes per world, explicit save/discard.
* :func:`load_episode` / :func:`validate_path` - read and check episode files.
* :func:`replay_episode` - re-simulate an episode from its recorded config, seed and actions.
* :func:`to_lerobot` - convert episodes to a LeRobot dataset; :func:`plot_episode` - Fig. 5 panels.
* :class:`LeRobotRecorder` - Gymnasium wrapper recording straight to a LeRobot dataset.
* CLIs: ``defgrasp-dataset`` (validate, to-lerobot, plot, replay, schema), ``defgrasp-generate``.
"""

from .reader import Episode, EpisodeFileError, list_episodes, load_episode
from .recorder import HDF5Recorder
from .vector_recorder import VectorHDF5Recorder
from .writer import EpisodeWriter
from .schema import FIELDS, FORMAT, SCHEMA_VERSION, schema_markdown
from .validate import ValidationReport, validate_episode, validate_path


def replay_episode(*args, **kwargs):
    """See :func:`defgrasp_env.recording.replay.replay_episode`."""
    from .replay import replay_episode as impl
    return impl(*args, **kwargs)


def to_lerobot(*args, **kwargs):
    """See :func:`defgrasp_env.recording.lerobot_export.to_lerobot` (imports lerobot lazily)."""
    from .lerobot_export import to_lerobot as impl
    return impl(*args, **kwargs)


def plot_episode(*args, **kwargs):
    """See :func:`defgrasp_env.recording.plot.plot_episode` (imports matplotlib lazily)."""
    from .plot import plot_episode as impl
    return impl(*args, **kwargs)


__all__ = ["EpisodeWriter", "HDF5Recorder", "VectorHDF5Recorder", "Episode", "EpisodeFileError", "load_episode", "list_episodes",
           "validate_episode", "validate_path", "ValidationReport", "replay_episode", "to_lerobot",
           "plot_episode", "FIELDS", "FORMAT", "SCHEMA_VERSION", "schema_markdown"]


def __getattr__(name: str):
    # LeRobotRecorder imports lerobot (slow): load on first use
    if name == "LeRobotRecorder":
        from .lerobot_recorder import LeRobotRecorder

        return LeRobotRecorder
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
