"""``PeriodGraph``: a pickup scene's control period as one graph on the simulation's device.

Per substep the graph runs what the scene's host loop runs (``PickupScene._advance_period``): the
gripper's plan, the first try as planned, its loads, the force limit's patient re-solve and its
retries with less motion, each decided on the device by the host's rules (``limit_kernels``), and
the acceptance (report, pad forces sensed). The same launches in the same order as the host's
loop: bit-identical on the CPU (``tests/test_period_graph.py``). The host downloads one small
``gate`` per period (its solve counts, and whether a solve left non-finite pad forces: the period
stops there and the host raises). Loops and branches are conditional graph nodes (CUDA with
conditional nodes, or Warp's CPU graphs): ``wp.capture_if`` / ``wp.capture_while`` on one-element
flags written by single-thread kernels.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import warp as wp

from ..gripper import Gripper
from ..gripper import gripper as gripper_module
from ..sim.launch_cache import LaunchCache
from ..sim.launch_lock import scoped_capture
from ..sim.solver import ImplicitSolver
from ..sim.state import Control, State
from ..wrist.force_limit import BACK_OFF, FORCE_TOLERANCE, MAX_RETRIES
from . import limit_loads
from . import limit_kernels as lk


@dataclass(frozen=True)
class PeriodRun:
    """What a period's graph did: the substeps it accepted (all unless a solve left non-finite pad
    forces), the solves it ran and the world-solves (worlds computed) of those solves."""

    accepted: int
    solves: int
    world_solves: int


class PeriodGraph:
    """The graph of a control period of ``num_worlds`` worlds, captured once per set of baked-in
    scalars (substeps, their length, the gripper's driver config and limits, the module constants
    its plan and the limit read) from the scene's parts: its ``solver``, ``gripper``, ``control``,
    the ``loads`` array that ``launch_loads(state)`` fills from a solve (``scene_kernels.solve_loads``),
    its ``launches`` cache and ``accept(k, state)`` (substep k's accepted solve: report, sensing).
    The first period with a set of scalars runs on the host (it loads the kernels and records the
    launches the graph replays): :meth:`run` returns None there."""

    def __init__(self, solver: ImplicitSolver, gripper: Gripper, control: Control, loads: wp.array,
                 launch_loads: Callable[[State], None], accept: Callable[[int, State], None], launches: LaunchCache):
        self.solver, self.gripper, self.control, self.loads = solver, gripper, control, loads
        self._launch_loads, self._accept, self._launches = launch_loads, accept, launches
        self.num_worlds = w = solver.model.num_worlds
        d = solver.model.device
        self.gate = wp.zeros(lk.GATE_SIZE, dtype=wp.int32, device=d)
        self._cond = {name: wp.zeros(1, dtype=wp.int32, device=d) for name in ("patient", "solve", "limit", "retry",
                                                                                "final")}
        self._patient_solved = wp.zeros(w, dtype=wp.int32, device=d)  # the world's last solve was patient
        self._limit = lk.LimitState()
        for name in ("scale", "lo", "hi", "f_lo", "f_hi", "side", "trial", "solved"):
            setattr(self._limit, name, wp.zeros(w, dtype=wp.float64, device=d))
        self._limit.searching = wp.zeros(w, dtype=wp.int32, device=d)
        self._graphs: dict = {}
        self._recorded: set = set()
        self.failed = False

    def run(self, states: tuple[State, State], count: int, h: float) -> PeriodRun | None:
        """The period's ``count`` substeps of ``h`` s from ``states[0]`` (they alternate: substep k
        writes ``states[(k + 1) % 2]``) as one graph launch; None where it must run on the host
        (the first period with these scalars, or a device without graphs or a failed capture)."""
        if not self.solver.graphs or self.failed:
            return None
        gripper = self.gripper
        key = (count, h, id(states[0]), id(states[1]), gripper.driver.config, gripper.wrist_force_limit,
               gripper_module.HOLD_COSINE, limit_loads.PATIENT_UPDATE_FRACTION, FORCE_TOLERANCE, MAX_RETRIES, BACK_OFF)
        graph = self._graphs.get(key)
        if graph is None:
            if key not in self._recorded:
                self._recorded.add(key)
                return None
            try:
                graph = self._graphs[key] = self._capture(states, count, h)
            except RuntimeError as exc:
                self.failed = True
                warnings.warn(f"capturing a control period as a graph failed on {self.solver.model.device} ({exc}); "
                              "stepping substep by substep from now on", RuntimeWarning, stacklevel=3)
                return None
        self.solver.select_all_worlds()
        wp.capture_launch(graph)
        gripper.device_state_changed()
        gate = self.gate.numpy()
        accepted = count if gate[lk.GATE_OPEN] else int(gate[lk.GATE_SUBSTEP])
        first_tries = count if gate[lk.GATE_OPEN] else accepted + 1
        return PeriodRun(accepted, first_tries + int(gate[lk.GATE_SOLVES]),
                         first_tries * self.num_worlds + int(gate[lk.GATE_WORLD_SOLVES]))

    # -- capture -----------------------------------------------------------------------------
    def _capture(self, states: tuple[State, State], count: int, h: float):
        d = self.solver.model.device
        wp.launch(lk.open_period_gate, dim=1, inputs=[self.gate], device=d)  # loads the module before the capture
        with scoped_capture(device=d, force_module_load=False) as capture:
            self._launch("open", lk.open_period_gate, 1, [], [self.gate])
            for k in range(count):
                wp.capture_if(self.gate, on_true=functools.partial(
                    self._substep, k, count, states[k % 2], states[(k + 1) % 2], h))
        return capture.graph

    def _loads(self, state: State) -> None:
        """A solve's loads (the scene's ``launch_loads``) and its non-finite worlds counted."""
        self._launch_loads(state)
        self._launch("count non-finite", lk.count_nonfinite, self.num_worlds, [self.loads], [self.gate])

    def _launch(self, name: str, kernel, dim: int, inputs: list, outputs: list) -> None:
        self._launches.launch(("period", name, *(v for v in inputs if isinstance(v, (int, float)))), kernel, dim,
                              inputs, outputs)

    def _substep(self, k: int, count: int, src: State, dst: State, h: float) -> None:
        """Substep ``k`` of ``count`` from ``src`` into ``dst``: plan, first try, patient re-solve,
        the limit's retries where a world is over, its back-off where a stopped world still is, and
        acceptance unless a pad force is non-finite."""
        w, cond, last = self.num_worlds, self._cond, k == count - 1
        self._launch("mark", lk.mark_substep, 1, [k], [self.gate])
        self.gripper.plan_substep(k, count, h)
        self.gripper.move_as_planned()
        self.solver.launch_advance(src, dst, self.control, h, full_outputs=last)
        self._loads(dst)
        self._patient(src, dst, h, last, first=True)
        self._launch("limit begin", lk.limit_begin, w, [self.loads, self.gripper.move_fraction, FORCE_TOLERANCE,
                                                         self._limit], [self.gate])
        self._launch("limit gate", lk.limit_gate, 1, [], [self.gate, cond["limit"], cond["retry"], cond["final"]])
        wp.capture_if(cond["limit"], on_true=functools.partial(self._limited, src, dst, h, last))
        self.gripper.aim_back_off(dst.pad_force)  # every world, as the host does where one may back off
        self._launch("back off begin", lk.back_off_begin, w, [self.loads, self.gripper.back_off_aim, FORCE_TOLERANCE,
                                                               BACK_OFF, self._limit], [self.gate])
        self._launch("back off gate", lk.limit_gate, 1, [], [self.gate, cond["limit"], cond["retry"], cond["final"]])
        wp.capture_if(cond["limit"], on_true=functools.partial(self._limited, src, dst, h, last))
        self._launch("non-finite", lk.close_gate_if_nonfinite, 1, [], [self.gate])
        wp.capture_if(self.gate, on_true=functools.partial(self._accept, k, dst))

    def _patient(self, src: State, dst: State, h: float, last: bool, first: bool) -> None:
        """The patient re-solve of the worlds ``choose_patient`` marks after a solve."""
        s, w = self.solver.scratch, self.num_worlds
        tolerance = self.solver.config.newton_tolerance
        self._launch("choose patient", lk.choose_patient, w,
                     [self.loads, self.gripper.move_fraction, self._patient_solved, int(first), s.unconverged,
                      s.diverged, FORCE_TOLERANCE, limit_loads.PATIENT_UPDATE_FRACTION, tolerance],
                     [s.patient, s.patient_update, self.gate])
        self._launch("patient gate", lk.patient_gate, 1, [], [self.gate, self._cond["patient"]])

        def solve():  # the last move stays: the host's re-solve moves by the same fraction
            self._launch("begin patient", lk.begin_patient_solve, w, [s.patient], [s.solve_worlds])
            self.solver.launch_advance(src, dst, self.control, h, full_outputs=last, patient=True)
            self._loads(dst)
            end()

        def end():  # also where none ran: patient marks never outlive the choice
            self._launch("end patient", lk.end_patient_solve, w, [s.patient],
                         [self._patient_solved, s.solve_worlds])

        wp.capture_if(self._cond["patient"], on_true=solve, on_false=end)

    def _limited(self, src: State, dst: State, h: float, last: bool) -> None:
        """``limited_substep``'s retries while a world searches, then the solve of the scales
        unless a retry was accepted as it was."""
        cond = self._cond

        def retry():
            self._limit_solve(src, dst, h, last, use_scale=False)
            self._launch("limit update", lk.limit_update, self.num_worlds, [self.loads, FORCE_TOLERANCE, self._limit],
                         [self.gate])
            self._launch("retry gate", lk.retry_gate, 1, [MAX_RETRIES], [self.gate, cond["retry"], cond["final"]])

        wp.capture_while(cond["retry"], retry)
        wp.capture_if(cond["final"], on_true=functools.partial(self._limit_solve, src, dst, h, last, use_scale=True))

    def _limit_solve(self, src: State, dst: State, h: float, last: bool, use_scale: bool) -> None:
        """One of the limit's solves (``limited_substep``'s ``solve``): the trial fraction moved to,
        the worlds whose fraction changed re-solved, the loads, the patient re-solve."""
        s, w, cond = self.solver.scratch, self.num_worlds, self._cond
        self._launch("trial", lk.limit_trial, w, [int(use_scale), self._limit],
                     [self.gripper.move_fraction, s.solve_worlds, self._patient_solved, self.gate])
        self._launch("solve gate", lk.solve_gate, 1, [], [self.gate, cond["solve"]])
        self.gripper.move_as_planned()
        wp.capture_if(cond["solve"], on_true=functools.partial(self.solver.launch_advance, src, dst, self.control, h,
                                                               full_outputs=last))
        self._launch("select all", lk.select_all_worlds, w, [], [s.solve_worlds])
        self._loads(dst)
        self._patient(src, dst, h, last, first=False)
