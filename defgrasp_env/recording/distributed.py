"""``defgrasp-generate --ray``: the same episodes as a serial run, recorded by the workers of a Ray cluster.

One Ray task per episode file, or (``--worlds N``) per group of up to N episodes of one (object, E).
Each task runs :func:`generate.record_jobs` for its jobs in a Ray worker process (its own env, a
single env or a native vector env with a world per episode; one CPU, or one GPU when ``device`` is
CUDA), so every file is written by the same code, with the same seed, as in a serial run: every
dataset of every file is bit-identical on the CPU (a world of a vector env steps as a single env on
its seed, and an episode does not depend on what the env recorded before); only the recorder's
bookkeeping differs: each task records in a fresh env (``episode_index``, ``world``, no
``scene_origin`` in the replay data).
Ray schedules the tasks on the cluster's resources and retries a task whose worker process or node
died (``max_retries``); a task whose file exists already (a resumed run, or a retry after its file
was published) returns at once. Files appear atomically (``atomic.py``): a worker killed at any
moment leaves at most a hidden temp file, which the next run removes (its writer's pid is checked on
the driver's machine: run one command per folder at a time), and a re-run records only the missing
files.

The output folder must be one shared file system path on every node (NFS or similar) when the
cluster has several machines. The driver ships its ``defgrasp_env`` package to the workers
(``runtime_env`` ``py_modules``; not when Ray was initialised in the process before), so every node
runs the driver's code; the dependencies (``pip install defgrasp[ray]``) must be installed on every
node.

A cluster of several machines (the same Python environment on each, OUT on a shared file system)::

    head$   ray start --head --port=6379
    node$   ray start --address=HEAD_IP:6379          # on every other machine
    head$   defgrasp-generate OUT --objects cuboid,torus --moduli 1e4,1e5 --episodes 50 --ray auto
    head$   ray stop                                   # on every machine, when done

With ``--device cuda`` each worker gets one GPU (``ray start --num-gpus=N`` where Ray does not
detect them). Without an address, ``--ray`` starts a local Ray on this machine (``--workers N``
CPUs; default all).
"""

from __future__ import annotations

import os
import pathlib
import signal
import threading

from .generate import Job, job_groups, progress_bar, record_jobs

DEFAULT_MAX_RETRIES = 3
#: Seconds between the driver's checks for Ctrl-C while it waits on Ray.
INTERRUPT_POLL_S = 0.25


def _import_ray():
    try:
        import ray
    except ImportError as exc:
        raise ImportError("--ray needs the optional dependency ray: pip install 'defgrasp[ray]'") from exc
    return ray


def record_group(out: str, jobs: list[Job], policy_spec: str, max_steps: int | None, device: str,
                 record_frames: bool, compression: str | None,
                 action_mode: str = "delta") -> list[tuple[str, bool | None]]:
    """Body of one Ray task: record the ``jobs`` (of one (object, E)) whose files are missing into
    ``out``, together in one vector env when there are several (``generate.record_jobs``); return
    (file name, success) per job, success None when its file was there already."""
    from .cli import default_caches

    default_caches()
    todo = [j for j in jobs if not (pathlib.Path(out) / j.name).exists()]
    result: dict[str, bool] = {}
    record_jobs(pathlib.Path(out), todo, policy_spec, max_steps, device, record_frames, compression,
                on_episode=lambda job, success: result.__setitem__(job.name, success), worlds=max(len(todo), 1),
                action_mode=action_mode)
    return [(j.name, result.get(j.name)) for j in jobs]


def _worker_device(device: str) -> tuple[str, float]:
    """The device a task uses and the GPUs it asks Ray for: Ray gives a CUDA task one GPU of its
    own (``CUDA_VISIBLE_DEVICES``), which the task sees as ``cuda``."""
    if device == "cpu":
        return "cpu", 0.0
    if device in ("cuda", "cuda:0"):
        return "cuda", 1.0
    raise ValueError(f"with --ray, --device must be 'cpu' or 'cuda' (Ray assigns each worker one GPU), got {device!r}")


class _CtrlC:
    """While the driver talks to Ray, Ctrl-C (SIGINT) only sets ``interrupted``; the driver checks it
    between ``ray.wait`` polls and after starting Ray, and raises ``KeyboardInterrupt`` from its own
    code, then cancels and shuts down. A ``KeyboardInterrupt`` raised inside Ray's C++ calls can fail
    one of Ray's internal checks and end the process with exit code 1 and a stack trace instead of a
    clean stop. A second Ctrl-C interrupts at once, except while shutting down (``stopping``).
    Nothing is installed off the main thread (no signal handler allowed there) or where SIGINT is
    ignored (``nohup``, a background job) or handled outside Python."""

    def __init__(self):
        self.interrupted = threading.Event()
        self.stopping = False
        self._previous = None

    def _on_sigint(self, signum, frame):
        if self.interrupted.is_set() and not self.stopping:
            raise KeyboardInterrupt
        self.interrupted.set()

    def __enter__(self) -> _CtrlC:
        if threading.current_thread() is threading.main_thread():
            previous = signal.getsignal(signal.SIGINT)
            if previous not in (signal.SIG_IGN, None):
                self._previous = signal.signal(signal.SIGINT, self._on_sigint)
        return self

    def __exit__(self, *exc) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)


def _start_ray(ray, address: str | None, workers: int | None) -> bool:
    """Connect to ``address`` (``auto``: the cluster started on this machine by ``ray start``) or
    start a local one with ``workers`` CPUs; return whether this call started Ray."""
    if ray.is_initialized():
        return False
    import defgrasp_env

    runtime_env = {"py_modules": [str(pathlib.Path(defgrasp_env.__file__).parent)]}
    if address is None:
        ray.init(num_cpus=workers or os.cpu_count(), include_dashboard=False, runtime_env=runtime_env,
                 log_to_driver=False)
    else:
        ray.init(address=address, runtime_env=runtime_env, log_to_driver=False)
    return True


def run_jobs_ray(out: pathlib.Path, jobs: list[Job], policy_spec: str, max_steps: int | None = None,
                 device: str = "cpu", record_frames: bool = False, compression: str | None = None,
                 progress: bool = True, *, address: str | None = None, workers: int | None = None,
                 max_retries: int = DEFAULT_MAX_RETRIES, worlds: int = 1,
                 action_mode: str = "delta") -> list[pathlib.Path]:
    """Record every job whose file is missing on a Ray cluster; return the files of all jobs.

    Args:
        worlds: episodes of one (object, E) per task, recorded together in a vector env of that
            many worlds (1: one episode per task, in a single env).
        address: Ray cluster address (``auto``, ``HOST:6379``, ``ray://HOST:10001``); None starts a
            local Ray with ``workers`` CPUs (all CPUs when None).
        workers: at most this many tasks at once, each one episode or a group of ``worlds`` (None: as
            many as the cluster's CPUs or GPUs allow).
        max_retries: times Ray re-runs an episode whose worker process or node died.
        action_mode: the env's action mode (``generate.record_jobs``).
    Raises:
        the first failed task's own exception (e.g. ``ValueError`` for a bad policy), or ``RuntimeError`` when a
        task's worker died more than ``max_retries`` times; files finished before stay.
    """
    from .atomic import check_writable_directory, remove_stale_temps

    if workers is not None and workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if isinstance(worlds, bool) or not isinstance(worlds, int) or worlds < 1:
        raise ValueError(f"worlds must be an integer >= 1, got {worlds!r}")
    if max_retries < 0:
        raise ValueError(f"max_retries must be >= 0, got {max_retries}")
    task_device, gpus = _worker_device(device)
    ray = _import_ray()
    out = check_writable_directory(out)
    remove_stale_temps(out)
    todo = [j for j in jobs if not (out / j.name).exists()]
    if not todo:
        return [out / j.name for j in jobs]
    queue, pending = list(reversed(job_groups(todo, worlds))), []
    limit = workers or len(queue)  # Ray's own pattern to bound pending tasks: ray.wait
    by_name = {j.name: j for j in todo}
    bar, started = None, False
    with _CtrlC() as ctrl_c:
        try:
            started = _start_ray(ray, address, workers)
            if ctrl_c.interrupted.is_set():
                raise KeyboardInterrupt
            task = ray.remote(record_group).options(num_cpus=1, num_gpus=gpus, max_retries=max_retries,
                                                  retry_exceptions=False)
            bar, on_episode = progress_bar(len(jobs), len(jobs) - len(todo), progress)
            _drain(ray, task, queue, pending, limit, ctrl_c.interrupted, on_episode, by_name, max_retries,
                   (str(out.resolve()), policy_spec, max_steps, task_device, record_frames, compression,
                    action_mode))
        except BaseException:
            ctrl_c.stopping = True
            if not started:  # a Ray started here stops below with its workers; a cluster's keep running
                for ref in pending:
                    ray.cancel(ref, force=True)
            raise
        finally:
            ctrl_c.stopping = True
            if bar is not None:
                bar.close()
            if started:
                ray.shutdown()
    return [out / j.name for j in jobs]


def _drain(ray, task, queue: list[list[Job]], pending: list, limit: int, interrupted: threading.Event, on_episode,
           by_name: dict[str, Job], max_retries: int, task_args: tuple) -> None:
    """Keep at most ``limit`` tasks pending until ``queue`` and ``pending`` are empty (``pending`` is
    updated in place, so the caller can cancel what is left); raise ``KeyboardInterrupt`` when
    ``interrupted`` is set."""
    out, *rest = task_args  # the arguments of record_group after its jobs
    while queue or pending:
        while queue and len(pending) < limit:
            pending.append(task.remote(out, queue.pop(), *rest))
        done, pending[:] = ray.wait(pending, num_returns=1, timeout=INTERRUPT_POLL_S)
        if interrupted.is_set():  # tasks in ``done`` have published their files
            raise KeyboardInterrupt
        for ref in done:
            try:
                results = ray.get(ref)
            except ray.exceptions.RayTaskError as exc:  # the task's own exception, without Ray's wrapper
                raise (exc.cause if isinstance(exc.cause, Exception) else exc) from exc
            except ray.exceptions.RayError as exc:  # worker or node lost more than max_retries times
                raise RuntimeError(f"a Ray task failed after {max_retries} retries: {exc}") from exc
            for name, success in results:
                if on_episode is not None and success is not None:  # None: the file was there already
                    on_episode(by_name[name], bool(success))
