"""``LAUNCH_LOCK``: Warp launches from several threads, and graph captures that see none of them.

A ``ShardedVectorEnv`` (``envs/sharded_vector_env.py``) steps several vector envs at once, one
thread each (on a multi-core CPU, or one GPU each). Warp's kernels are reentrant and its launches
release the GIL, but on the CPU a graph capture is the process's: while one is open
(``wp.ScopedCapture``), every launch of any thread is recorded into it instead of run, and a second
capture is refused (``Graph capture already in progress``). On CUDA a capture records its own
stream, so there the lock serialises more than needed. So every thread that launches holds the lock
shared
(``LAUNCH_LOCK.shared()``, around a whole env step or reset), and every capture holds it
exclusively (``LAUNCH_LOCK.capturing()``): a capture waits until the other threads have finished
their current step, and they wait for it. A thread that captures while it holds the lock shared
(the capture sites are inside an env step) lets go of its shared hold for the capture and takes it
back after. With one thread (the single env, one vector env) the lock is never contended.
"""

from __future__ import annotations

import contextlib
import threading

import warp as wp

__all__ = ["LAUNCH_LOCK", "LaunchLock", "scoped_capture"]


class LaunchLock:
    """A readers-writer lock: launches share it, a graph capture holds it alone. Writers take
    precedence (a thread asking for a shared hold waits while a capture waits), so a capture is
    not starved by threads that step back to back. Shared holds are counted per thread (nested
    ``shared()`` is allowed)."""

    def __init__(self):
        self._cond = threading.Condition()
        self._readers = 0         # shared holds, all threads
        self._writer = False      # a capture holds the lock
        self._waiting_writers = 0
        self._writer_thread = None  # the thread holding it exclusively
        self._local = threading.local()

    def _held(self) -> int:
        return getattr(self._local, "held", 0)

    def _acquire_shared(self, count: int) -> None:
        with self._cond:
            while self._writer or self._waiting_writers:
                self._cond.wait()
            self._readers += count
        self._local.held = self._held() + count

    def _release_shared(self, count: int) -> None:
        with self._cond:
            self._readers -= count
            self._cond.notify_all()
        self._local.held = self._held() - count

    @contextlib.contextmanager
    def shared(self):
        """Hold while launching Warp kernels from a thread that may run beside others."""
        if self._held() or self._writer_thread == threading.get_ident():
            # nested, or inside this thread's own capture: captures are already kept apart
            yield
            return
        self._acquire_shared(1)
        try:
            yield
        finally:
            self._release_shared(1)

    @contextlib.contextmanager
    def capturing(self):
        """Hold while capturing a Warp graph: no other thread launches meanwhile. A capture inside
        a capture of the same thread is refused (RuntimeError, as Warp refuses nested captures)."""
        if self._writer_thread == threading.get_ident():
            raise RuntimeError("Graph capture already in progress in this thread (LAUNCH_LOCK)")
        held = self._held()
        if held:
            self._release_shared(held)
        with self._cond:
            self._waiting_writers += 1
            try:
                while self._writer or self._readers:
                    self._cond.wait()
            finally:
                self._waiting_writers -= 1
            self._writer = True
            self._writer_thread = threading.get_ident()
        try:
            yield
        finally:
            with self._cond:
                self._writer = False
                self._writer_thread = None
                self._cond.notify_all()
            if held:
                self._acquire_shared(held)


#: The process's lock (Warp's capture state is the process's).
LAUNCH_LOCK = LaunchLock()


@contextlib.contextmanager
def scoped_capture(**kwargs):
    """``wp.ScopedCapture(**kwargs)`` holding ``LAUNCH_LOCK`` exclusively: every graph capture of
    the package goes through here."""
    with LAUNCH_LOCK.capturing(), wp.ScopedCapture(**kwargs) as capture:
        yield capture
