"""``defgrasp-teleop``: the demonstration collection app on top of the teleop package.

* ``cli``: the command line (``defgrasp-teleop`` / ``python -m teleop``);
* ``session``: ``CollectionSession``, the loop (keys -> episode flow, act -> step -> haptics,
  recording through ``HDF5Recorder``, live view, Ctrl-C safety);
* ``control``: the episode flow as a pure state machine; ``keys``: the pure key -> command map and
  key sources (pynput, terminal, none, scripted);
* ``devices``: ``--tracker``/``--glove`` specs -> a ``TeleopDevice``; ``view``: the live views (3D browser
  viewer, camera-image page, PNG file).

Synthetic operator streams and playing recorded streams over UDP live in ``teleop.testing``.

Importing this package does not import the simulator; the submodules that need it do so lazily.
"""

from .control import Effect, EpisodeControl, Phase
from .keys import DEFAULT_RECORD_KEYS, RecordCommand, command_for_key, commands_for_keys, decode_terminal_keys, make_key_source

__all__ = [
    "DEFAULT_RECORD_KEYS", "Effect", "EpisodeControl", "Phase", "RecordCommand", "command_for_key", "commands_for_keys",
    "decode_terminal_keys", "make_key_source",
]
