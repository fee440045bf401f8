"""A policy for crash tests: random actions (as ``--policy random``), but the first episode that
reaches step 3 anywhere SIGKILLs its own process once (claimed through an O_EXCL marker file in
``$DEFGRASP_CRASH_DIR``), as a worker that dies mid-episode would."""

from __future__ import annotations

import os
import pathlib
import signal

from defgrasp_env.recording.generate import RandomPolicy


class CrashOncePolicy(RandomPolicy):
    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.steps = 0

    def __call__(self, obs):
        self.steps += 1
        if self.steps == 3:
            marker = pathlib.Path(os.environ["DEFGRASP_CRASH_DIR"]) / "crashed"
            try:
                fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                return super().__call__(obs)
            os.write(fd, str(os.getpid()).encode())
            os.close(fd)
            os.kill(os.getpid(), signal.SIGKILL)
        return super().__call__(obs)
