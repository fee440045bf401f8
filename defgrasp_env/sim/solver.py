"""Implicit (backward Euler) FEM solver: a thin launcher over the kernels.

Each substep solves  M/h^2 (x - x_start - h v) = f_elastic(x) + f_contact(x) + M g + f_ext  for x by
Newton's method (projected elastic Hessian, exact contact normal Hessian, lagged friction), each
Newton system by CG preconditioned by block Jacobi plus a coarse solve on the rigid motions of node
aggregates (kernels/linear_solve.py, kernels/coarse_space.py, sim/aggregates.py), a backtracking
line search on the incremental potential (kernels/energy.py, kernels/line_search.py), all per world.
The scratch arrays are a ``SolverScratch``; the launches of each phase of a substep are recorded by
``solver_launches``; the loops' exit tests run on the device (``solver_loops``), so that a whole
``advance`` is captured once as a graph (a CUDA graph with conditional nodes, or a Warp CPU graph)
and replayed with one launch.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import warp as wp

from .launch_lock import scoped_capture
from .materials import check_range
from .model import Model
from .solve_report import SolveReport, SolveStats
from .solver_launches import SubstepLaunches, record_substep_launches
from .solver_loops import DeviceLoops
from .solver_scratch import SolverScratch
from .state import Control, State
from .world_compaction import WorldCompaction

__all__ = ["ImplicitSolver", "SolveStats", "SolverConfig"]

#: Launch sets (one per substep length and (state_in, state_out, control) triple) kept at most.
_LAUNCH_SETS = 8
#: ``SolverConfig.listed_cg_worlds`` on CUDA when it is None.
LISTED_CG_WORLDS_CUDA = 8
#: ``SolverConfig.world_block_threads`` when it is None, by device kind; on CUDA 256 up to
#: ``MANY_WORLDS`` worlds and 128 beyond (fewer threads per world, more worlds resident at once).
#: Measured on an H200 (benchmarks/RESULTS.md): 256 against 128 threads, W = 1 random actions
#: 1.8 / 2.0 ms a step, W = 2048 contact-heavy 119 / 137 ms (mean), W = 4096 random 58.3 / 54.4 ms.
WORLD_BLOCK_THREADS = {"cuda": 256, "cpu": 1}
WORLD_BLOCK_THREADS_MANY = 128
MANY_WORLDS = 2048
#: The largest ``SolverConfig.world_block_threads``: a block of 256 threads fits in an SM's 64 K
#: registers at any register count (at most 255 a thread); 1024 failed to launch on an H200.
MAX_WORLD_BLOCK_THREADS = 256
#: The largest ``SolverConfig.cg_block_threads``: the world-block CG kernel alone uses ~96 registers
#: a thread (H200, warp 1.19), so a block of 512 fits an SM's 64 K registers; 1024 would need <= 64.
MAX_CG_BLOCK_THREADS = 512


@dataclass(frozen=True)
class SolverConfig:
    """Iteration limits and tolerances of the implicit solver.

    Attributes:
        substeps: backward-Euler substeps per call of ``step``.
        newton_iterations: Newton iterations per substep at most.
        newton_tolerance: a world's Newton loop stops once the largest node update of its full Newton
            step (before the line search shortens it) is below this, m.
        cg_iterations: CG iterations per Newton iteration at most.
        cg_tolerance: CG stops once r.z falls below eta^2 of its initial value, eta (the forcing
            term of an inexact Newton method) = cg_tolerance times the world's last Newton update in
            this substep (none at its first iteration) over ``newton_tolerance``, at least
            cg_tolerance and at most ``cg_tolerance_far``: a world whose last update was near the
            tolerance (it is converging; the convergence test and a converged solve's contact
            forces rest on this step) solves to cg_tolerance, one far from it takes a rougher step
            that the next Newton iteration corrects.
        cg_tolerance_far: the loosest eta (if at most cg_tolerance, eta is cg_tolerance always).
            1e-2: the operator's soft-cube episode takes the same Newton iterations as with 1e-3 everywhere
            and 23 % fewer CG iterations (its rope 19 %); 3e-2 saved more but let a stiff cube's
            wrist force in the contact fuzz read 308 N where 1e-3 and 1e-2 read 192 / 186 N
            (benchmarks/RESULTS.md, "An inexact Newton step"). A ``patient`` world (``advance``)
            solves every CG to cg_tolerance.
        cg_update_fraction: CG also stops, from its 8th iteration on, after an iteration that moved no
            node by more than this fraction of ``newton_tolerance`` (r.z alone cannot fall below
            float32 noise near a solution).
        max_node_step: a Newton update longer than this (m) marks the world as diverged.
        line_search_steps: halvings of a Newton step at most while it raises the energy.
        penetration_bound: no node ends a substep deeper than this (m) inside a pad's collision box
            (behind its contact face) or below the ground: a solve that leaves one deeper has it put
            back to 90 % of this depth and is flagged (``SolveStats.penetrated``).
        penetration_iterations: extra Newton iterations at most per substep, after
            ``newton_iterations``, in the worlds whose iterate is still deeper than half of
            ``penetration_bound`` (a violent contact the regular iterations did not resolve).
        patient_iterations: extra Newton iterations at most per substep, after
            ``newton_iterations``, in the worlds a ``step`` or ``advance`` call marks ``patient``, while their update
            is above ``newton_tolerance`` or the call's larger ``patient_update`` (a caller that needs
            the contact forces of a converged solve: an unconverged iterate of a stiff contact can
            read kN where the solution reads tens of N).
        check_every: test every this many CG iterations, and after every Newton iteration and
            line-search trial, whether all worlds are done (0 = never: run the full iteration
            counts). The tests run on the device (``solver_loops``): inside the captured graph of
            a step they cost no host round trip.
        listed_cg_worlds: once at most this many worlds of a batch still iterate CG (checked every
            ``check_every`` iterations), its launches run over the rows of those worlds only
            (``world_compaction``; 0 = never; only where the model has more worlds, and on CUDA only
            where the step is captured as a graph: outside one the test is a host round trip). The
            same rows by the same code: bit-identical on the CPU; on a GPU a launch then costs what a
            few worlds' rows cost instead of a thread per row of every world. None (default):
            ``LISTED_CG_WORLDS_CUDA`` on CUDA, 0 on the CPU (where it measured slower: W = 48 on a
            2-core CPU, 4-19 % longer solves; benchmarks/RESULTS.md).
        world_block_threads: each world's Newton iteration in three launches
            (``kernels/world_evaluate.py``, ``world_cg.py``, ``world_newton_step.py``): a block of
            this many threads per world evaluates, runs its CG iterations, and its coarse
            correction, line-search trials and update, each to its own stopping test, with block
            barriers between the phases, instead of eleven to fifteen launches for the evaluation,
            four or five per CG iteration and seven per line-search trial over the rows of all worlds
            while any world iterates (``listed_cg_worlds`` and, inside a Newton iteration,
            ``check_every`` are then unused); also a substep's start and end in one launch each
            (``world_start.py``: copies, pad poses, guess, contact lag and guess fixes, up to 16
            launches; ``world_finish.py``: clamp, velocities, outputs, up to 11). 0 = off. On CUDA
            the block size (1 to 256, a multiple of 32 above 32); on the CPU, which runs a launch's
            threads one after another, any positive value means one thread per world (as configured
            only where ``wp.config.enable_cpu_blocks`` runs several threads per block), and the
            results are bit-identical to the phase-by-phase launches. None (default):
            ``WORLD_BLOCK_THREADS`` of the device's kind (on CUDA ``WORLD_BLOCK_THREADS_MANY``
            beyond ``MANY_WORLDS`` worlds).
        cg_block_threads: threads per world of the world blocks' CG launch
            (``kernels/world_cg.py``), where ``world_block_threads`` is on: up to
            ``MAX_CG_BLOCK_THREADS`` (its kernel needs fewer registers than the evaluation's and the
            Newton step's, which stay at ``world_block_threads``), a multiple of 32 above 32. None
            (default): ``world_block_threads``. The CPU runs one thread per world either way.
            Measured on an H100 (benchmarks/RESULTS.md, 2026-12-06): 512 against 256 made a lone
            pressing rope's step 7 % shorter (mean 30.4 -> 28.4 ms) and the cuboid's at W = 1 no
            shorter, but a W = 2000 batch 7 % and W = 4096 13 % longer (fewer worlds resident per
            SM): hence not the default.
        graphs: capture each ``ImplicitSolver.advance`` as one graph and replay it (None: where
            the device can: CUDA with driver and toolkit >= 12.4 for conditional nodes, or Warp's
            CPU graphs). The results are those of the launches one by one (bitwise on the CPU).
    """

    substeps: int = 2
    newton_iterations: int = 4
    newton_tolerance: float = 1e-5
    cg_iterations: int = 40
    cg_tolerance: float = 1e-3
    cg_tolerance_far: float = 1e-2
    cg_update_fraction: float = 1e-3
    max_node_step: float = 0.5
    line_search_steps: int = 8
    check_every: int = 4
    penetration_bound: float = 1e-3
    penetration_iterations: int = 8
    patient_iterations: int = 60
    listed_cg_worlds: int | None = None
    world_block_threads: int | None = None
    cg_block_threads: int | None = None
    graphs: bool | None = None

    def __post_init__(self) -> None:
        counts = [("substeps", 1), ("newton_iterations", 1), ("cg_iterations", 1), ("line_search_steps", 0),
                  ("check_every", 0), ("penetration_iterations", 0), ("patient_iterations", 0)]
        if self.listed_cg_worlds is not None:  # None: the device's default
            counts.append(("listed_cg_worlds", 0))
        if self.world_block_threads is not None:
            counts.append(("world_block_threads", 0))
        if self.cg_block_threads is not None:
            counts.append(("cg_block_threads", 1))
        for name, low in counts:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
        threads = self.world_block_threads
        if threads is not None and (threads > MAX_WORLD_BLOCK_THREADS or (threads > 32 and threads % 32)):
            raise ValueError(f"world_block_threads must be 0 (off), 1 to 32, or a multiple of 32 up to "
                             f"{MAX_WORLD_BLOCK_THREADS} (a CUDA thread block per world), got {threads}")
        cg = self.cg_block_threads
        if cg is not None and (cg > MAX_CG_BLOCK_THREADS or (cg > 32 and cg % 32)):
            raise ValueError(f"cg_block_threads must be 1 to 32 or a multiple of 32 up to {MAX_CG_BLOCK_THREADS} "
                             f"(a CUDA thread block per world in CG), got {cg}")
        check_range("newton_tolerance", self.newton_tolerance, 0.0, math.inf, "m")
        check_range("cg_tolerance", self.cg_tolerance, 0.0, 1.0)
        check_range("cg_tolerance_far", self.cg_tolerance_far, 0.0, 1.0)
        check_range("cg_update_fraction", self.cg_update_fraction, 0.0, 1.0, low_open=False, high_open=False)
        check_range("max_node_step", self.max_node_step, 0.0, math.inf, "m")
        check_range("penetration_bound", self.penetration_bound, 0.0, math.inf, "m")
        if self.graphs is not None and not isinstance(self.graphs, bool):
            raise ValueError(f"graphs must be True, False or None (where the device can), got {self.graphs!r}")


def graphs_supported(device) -> bool:
    """Whether a whole ``advance`` (loops with device-side exit tests) can be one graph on ``device``:
    CUDA graphs with conditional nodes (driver and toolkit >= 12.4), or Warp's CPU graphs with
    ``capture_while`` and ``capture_if`` (tried once per process)."""
    device = wp.get_device(device)
    if device.is_cuda:
        return wp.is_conditional_graph_supported()
    global _CPU_GRAPHS
    if _CPU_GRAPHS is None:
        flag = wp.zeros(1, dtype=wp.int32, device=device)
        try:
            with scoped_capture(device=device, force_module_load=False) as capture:
                wp.capture_while(flag, lambda: flag.zero_())
                wp.capture_if(flag, on_true=lambda: flag.zero_(), on_false=lambda: flag.zero_())
            wp.capture_launch(capture.graph)
            _CPU_GRAPHS = True
        except (RuntimeError, NotImplementedError, TypeError, AttributeError):
            _CPU_GRAPHS = False
    return _CPU_GRAPHS


_CPU_GRAPHS: bool | None = None


def default_world_block_threads(device, worlds: int) -> int:
    """``SolverConfig.world_block_threads`` where it is None, for ``worlds`` worlds on ``device``."""
    if wp.get_device(device).is_cpu:
        return WORLD_BLOCK_THREADS["cpu"]
    return WORLD_BLOCK_THREADS["cuda"] if worlds <= MANY_WORLDS else WORLD_BLOCK_THREADS_MANY


class ImplicitSolver:
    """Advances a ``State`` of a ``Model`` by ``dt`` under a ``Control``.

    Scratch arrays (``SolverScratch``) are made once per model and the kernel launches
    (``SubstepLaunches``) are recorded once per substep length and per (state_in, state_out,
    control) triple they are bound to (a few are kept), with the graph captured of them where the
    device supports it (one launch per call; otherwise a couple of microseconds of Python per
    launch and one host test per loop pass); a step copies no state besides the start positions
    and velocities.
    Usage::

        solver = ImplicitSolver(model, SolverConfig())
        stats = solver.step(state_in, state_out, control, dt=0.05)

    ``advance`` is ``step`` without the report's download: the report stays on the device, in
    ``scratch``, for ``SolveReport.fold`` (a caller that runs several solves per control step
    downloads one report per step).
    """

    def __init__(self, model: Model, config: SolverConfig = SolverConfig()):
        self.model = model
        self.config = config
        supported = graphs_supported(model.device)
        if config.graphs and not supported:
            need = ("a CUDA driver and toolkit >= 12.4 (conditional graph nodes)" if wp.get_device(model.device).is_cuda
                    else "a Warp that captures CPU graphs with capture_while (1.19+)")
            raise ValueError(f"SolverConfig(graphs=True) but device {model.device} cannot capture a step as one graph: "
                             f"it needs {need}; use graphs=None (where the device can) or False")
        self.graphs = supported if config.graphs is None else config.graphs
        is_cpu = wp.get_device(model.device).is_cpu
        threads = config.world_block_threads
        if threads is None:
            threads = default_world_block_threads(model.device, model.num_worlds)
        #: threads per world of the world blocks (``SolverConfig.world_block_threads``; 0: off; on the
        #: CPU 1, or as configured where ``wp.config.enable_cpu_blocks`` runs several per block)
        self.world_block_threads = min(threads, 1) if is_cpu and not wp.config.enable_cpu_blocks else threads
        cg_threads = threads if config.cg_block_threads is None else config.cg_block_threads
        #: threads per world of the world blocks' CG (``SolverConfig.cg_block_threads``; 0 where the
        #: world blocks are off, 1 on the CPU unless ``wp.config.enable_cpu_blocks``)
        self.cg_block_threads = (0 if not self.world_block_threads else
                                 1 if is_cpu and not wp.config.enable_cpu_blocks else cg_threads)
        self.scratch = SolverScratch.from_model(model, block_threads=self.world_block_threads)
        self.loops = DeviceLoops(model, config, self.scratch)
        capacity = config.listed_cg_worlds
        if capacity is None:
            capacity = 0 if is_cpu else LISTED_CG_WORLDS_CUDA
        self.compaction = WorldCompaction.from_model(model, capacity, self.scratch.edges.points_per_world)
        # outside a captured step, capture_if reads its condition on the host: free on the CPU, a
        # synchronisation per CG block on CUDA (where listing is then not used)
        self._listed_cg = (not self.world_block_threads and self.compaction.pays(model)
                           and (self.graphs or is_cpu))
        self._report = SolveReport(model.num_worlds, model.device)
        self._solving_all = True  # scratch.solve_worlds holds all ones
        self._launches: dict[tuple, tuple] = {}

    # -- public --------------------------------------------------------------------------------
    def step(self, state_in: State, state_out: State, control: Control, dt: float,
             patient: np.ndarray | None = None, worlds: np.ndarray | None = None,
             patient_update: np.ndarray | None = None) -> SolveStats:
        """Advance ``state_in`` by ``dt`` seconds into ``state_out`` (they may be the same object) and return
        the per-world report (one device-to-host copy); ``patient``, ``worlds`` and ``patient_update`` as for
        ``advance`` (the report of a world outside ``worlds`` is that of its last solve)."""
        self.advance(state_in, state_out, control, dt, patient, worlds, patient_update=patient_update)
        self._report.fold(self.scratch, self.config.penetration_bound, first=True)
        return self._report.download()

    def advance(self, state_in: State, state_out: State, control: Control, dt: float,
                patient: np.ndarray | None = None, worlds: np.ndarray | None = None,
                full_outputs: bool = True, patient_update: np.ndarray | None = None) -> None:
        """Advance ``state_in`` by ``dt`` seconds into ``state_out`` (they may be the same object; distinct,
        ``state_in`` is only read). Every array of ``state_out`` is written (the rows of the solved worlds;
        with ``full_outputs`` False all but the von Mises stresses and their mean); the report is left in
        ``scratch`` (``SolveReport.fold``). ``patient`` [W] bool (default none): worlds given up to
        ``config.patient_iterations`` extra Newton iterations per substep until their last update is
        at most ``patient_update`` [W] (m; default, and where smaller, ``newton_tolerance``: a caller
        that needs less than convergence, such as a decision that a smaller update settles, asks for
        a larger one); every other world's result is the same, bit for bit, as without it (its
        ``converged`` flag stays False when the regular iterations did not converge, even if the extra ones
        did). ``worlds`` [W] bool (default all): only these worlds are solved; every other world's rows of
        ``state_out`` and its report in ``scratch`` are left as they are (the solves of different worlds are
        independent, so a world solved again from the same input gets the same result, bit for bit on the
        CPU: a caller that re-solves some worlds, like the actuator force limit's retries, need not redo the
        others). ``full_outputs`` False: of the outputs at the returned positions only the contact part (pad
        loads, contact forces, the report's penetration); the elastic forces and the report's residual read
        0, the von Mises stresses and their mean keep their last values (a caller's intermediate substeps,
        whose next solve reads none of them). Where the device can (``graphs``), the whole call is one graph
        launch, captured at the first call with these states, control and ``dt``."""
        check_range("dt", dt, 0.0, math.inf, "s")
        s = self.scratch
        if not self._select_worlds(worlds):
            return
        patient_any = patient is not None and bool(np.any(patient))
        if patient_any:
            num_worlds, tol = self.model.num_worlds, self.config.newton_tolerance
            update = np.full(num_worlds, tol) if patient_update is None else np.asarray(patient_update, np.float64)
            if update.shape != (num_worlds,) or np.isnan(update).any():
                raise ValueError(f"patient_update must be {num_worlds} update sizes (m), not NaN, got {update!r}")
            s.patient.assign(np.asarray(patient, dtype=np.int32).reshape(num_worlds))
            s.patient_update.assign(np.maximum(update, tol).astype(np.float32))
        run, graphs = self._substep_launches(dt / self.config.substeps, state_in, state_out, control)
        key = (patient_any, bool(full_outputs))
        if self.graphs and key not in graphs:
            try:
                with scoped_capture(device=self.model.device, force_module_load=False) as capture:
                    self._advance(run, state_in, state_out, control, patient_any, full_outputs)
                graphs[key] = capture.graph
            except RuntimeError as exc:
                if self.config.graphs:
                    raise
                warnings.warn(f"capturing a solver step as a graph failed on {self.model.device} ({exc}); "
                              "stepping without graphs from now on", RuntimeWarning, stacklevel=2)
                self.graphs = False
                self._launches.clear()
                run, graphs = self._substep_launches(dt / self.config.substeps, state_in, state_out, control)
        if self.graphs:
            wp.capture_launch(graphs[key])
        else:
            self._advance(run, state_in, state_out, control, patient_any, full_outputs)
        if patient_any:
            s.patient.zero_()

    def select_all_worlds(self) -> None:
        """Select every world for the next solves (``advance`` with ``worlds=None`` does this
        itself; a caller replaying ``launch_advance`` inside its own graph calls it before)."""
        self._select_worlds(None)

    def launch_advance(self, state_in: State, state_out: State, control: Control, dt: float,
                       full_outputs: bool = True, patient: bool = False) -> None:
        """The launches of ``advance(state_in, state_out, control, dt, full_outputs=...)`` (``state_in``
        and ``state_out`` distinct) on the device's current stream, not its own graph: for a caller
        capturing them into a larger graph (``PickupScene``'s control period). Needs ``graphs``
        (the loops' exit tests on the device). The worlds solved are those ``scratch.solve_worlds``
        selects when the launches run (all after ``select_all_worlds``; a caller's kernel may write
        it); ``patient``: with ``config.patient_iterations`` extra iterations in the worlds
        ``scratch.patient`` marks, down to their ``scratch.patient_update`` (written by the caller's
        kernel as ``advance`` writes them; the caller clears ``patient`` after)."""
        if not self.graphs:
            raise RuntimeError("launch_advance needs a solver whose loops test on the device (graphs=True)")
        if state_in is state_out:
            raise ValueError("launch_advance needs distinct input and output states")
        check_range("dt", dt, 0.0, math.inf, "s")
        run, _ = self._substep_launches(dt / self.config.substeps, state_in, state_out, control)
        self._advance(run, state_in, state_out, control, patient, full_outputs)

    # -- internals ---------------------------------------------------------------------------
    def _select_worlds(self, worlds: np.ndarray | None) -> bool:
        """Set ``scratch.solve_worlds`` to ``worlds`` [W] bool (None: all); False if none is set."""
        s, w = self.scratch, self.model.num_worlds
        if worlds is None:
            if not self._solving_all:
                s.solve_worlds.fill_(1)
                self._solving_all = True
            return True
        worlds = np.asarray(worlds)
        if worlds.shape != (w,) or worlds.dtype != bool:
            raise ValueError(f"worlds must be a [{w}] bool mask of the worlds to solve, got {worlds.dtype} "
                             f"of shape {worlds.shape}")
        if not worlds.any():
            return False
        s.solve_worlds.assign(worlds.astype(np.int32))
        self._solving_all = bool(worlds.all())
        return True

    def _advance(self, run: SubstepLaunches, state_in: State, state_out: State, control: Control,
                 patient_any: bool, full_outputs: bool = True) -> None:
        cfg, s = self.config, self.scratch
        if state_in is state_out:  # the start positions are overwritten: keep them for the prescribed axes
            wp.copy(s.step_start, state_in.positions)
        for k in range(cfg.substeps):
            # the input's rows and a clear report (k = 0), pad poses, start and guess, lag, Newton's flags
            for cmd in run.start[k]:
                cmd.launch()
            self._newton(run, cfg.patient_iterations if patient_any else 0)
            last = k == cfg.substeps - 1
            for cmd in run.finish_contact if last and not full_outputs else run.finish[k]:
                cmd.launch()  # clamp, velocities, outputs after the last substep

    def _newton(self, run: SubstepLaunches, patient_iterations: int = 0) -> None:
        """The regular Newton iterations while a world iterates (all of them without checks), then
        the extra ones (``DeviceLoops.extra_iterations``) in the worlds that ran all regular ones."""
        self.loops.do_while("newton", lambda: self._newton_iteration(run, first=True),
                            lambda: self._newton_iteration(run, first=False))
        self.loops.extra_iterations(run.depth, lambda: self._newton_iteration(run, first=False), patient_iterations)

    def _newton_iteration(self, run: SubstepLaunches, first: bool) -> None:
        for cmd in run.evaluate_first if first else run.evaluate:
            cmd.launch()
        self._run_cg(run)
        if run.step_world:  # coarse correction, line search and update: one launch (world_block_threads)
            for cmd in run.step_world_first if first else run.step_world:
                cmd.launch()
            return
        for cmd in run.coarse_post:
            cmd.launch()
        self._line_search(run, first)
        for cmd in run.apply:
            cmd.launch()

    def _run_cg(self, run: SubstepLaunches) -> None:
        """Each world's CG in one launch (``world_block_threads``), or CG in blocks of
        ``run.cg_block`` iterations (a world stops at its own test or at ``cg_iterations``; later
        iterations of a block skip it) while a world iterates; a block runs over the listed worlds'
        rows once few still iterate (``listed_cg_worlds``)."""
        if run.cg_world:
            for cmd in run.cg_world:
                cmd.launch()
            return

        def over_all():
            for cmd in run.cg:
                cmd.launch()

        def over_listed():
            for cmd in run.cg_listed:
                cmd.launch()

        def block():
            for cmd in run.list_cg_worlds:
                cmd.launch()
            wp.capture_if(self.compaction.cond, on_true=over_listed, on_false=over_all)

        body = block if self._listed_cg else over_all
        self.loops.do_while("cg", body, body)

    def _line_search(self, run: SubstepLaunches, first: bool) -> None:
        """Per world, halve the Newton step until the incremental potential does not increase.
        The start energy is evaluated at the first Newton iteration of a substep (its tets' part by
        that iteration's evaluation, which computes their F and R anyway); later ones start from the
        energy of the step accepted last (kept by ``end_line_search_trial``)."""
        cfg = self.config
        if cfg.line_search_steps == 0:
            return
        if first:  # the tets' part was summed by the first evaluation (cleared there)
            for cmd in run.energy0:
                cmd.launch()
        run.begin_search.launch()

        def trial():
            for cmd in run.trial:
                cmd.launch()

        self.loops.do_while("search", trial, trial)

    def _substep_launches(self, h: float, state_in: State, state_out: State, control: Control) -> tuple:
        """Recorded launches for substeps of length ``h`` (s) from ``state_in`` into ``state_out``
        under ``control`` (the arrays they are bound to), and the graphs captured of them (by
        ``(patient_any, full_outputs)``); the least recently used set is dropped."""
        key = (h, id(state_in), id(state_out), id(control))
        entry = self._launches.pop(key, None)
        if entry is None or entry[0] is not state_in or entry[1] is not state_out or entry[2] is not control:
            step_start = self.scratch.step_start if state_in is state_out else state_in.positions
            entry = (state_in, state_out, control,
                     record_substep_launches(self.model, self.config, self.scratch, state_out, control, h,
                                             start_pads=(state_in.pad_positions, state_in.pad_orientations),
                                             step_start=step_start, compaction=self.compaction,
                                             listed_cg=self._listed_cg, phase_graphs=not self.graphs,
                                             world_block_threads=self.world_block_threads,
                                             cg_block_threads=self.cg_block_threads,
                                             copy_from=None if state_in is state_out else state_in), {})
        self._launches[key] = entry  # most recently used last
        while len(self._launches) > _LAUNCH_SETS:
            self._launches.pop(next(iter(self._launches)))
        return entry[3], entry[4]
