"""The loops of a substep's solve (Newton, CG, line search) with their exit tests on the device.

Every loop is a do-while whose condition is a one-element int32 array written by the kernels of
``kernels/loop_control.py`` and tested by ``wp.capture_while``: inside a graph capture (a CUDA graph
with conditional nodes, or a Warp CPU graph) the whole substep is one graph with no host round
trip; outside one, ``wp.capture_while`` tests the flag on the host (one small download per test on
CUDA). With ``SolverConfig.check_every == 0`` the "any world still iterating" tests always pass,
so every loop runs its full count.
"""

from __future__ import annotations

import warp as wp

from .kernels import loop_control as klc

#: The solver's loops, each with its own pass counter and condition.
LOOPS = ("newton", "cg", "search", "extra")


class DeviceLoops:
    """Flags, counters and the recorded control launches of the solver's loops on the model's
    device, all made once per solver (nothing is compiled or recorded during a graph capture).

    ``count[name]`` [1] int32 holds the passes of the last run of each loop (Newton's regular
    iterations, CG blocks, line-search trials, extra Newton iterations)."""

    def __init__(self, model, config, scratch):
        dev = model.device
        self.device = dev
        self.hit = wp.zeros(1, dtype=wp.int32, device=dev)
        self.count = {name: wp.zeros(1, dtype=wp.int32, device=dev) for name in LOOPS}
        self.cond = {name: wp.zeros(1, dtype=wp.int32, device=dev) for name in LOOPS}
        self.running = wp.zeros(1, dtype=wp.int32, device=dev)
        self.check = check = bool(config.check_every)
        w = model.num_worlds
        # the per-world flags each loop iterates while any is set
        flags = {"newton": scratch.newton_active, "cg": scratch.cg_active, "search": scratch.searching}
        self._any = {name: (self._rec(klc.flag_any, w, f, self.hit) if check else self._rec(klc.set_hit, 1, self.hit))
                     for name, f in flags.items()}
        cg_blocks = -(-config.cg_iterations // (config.check_every or config.cg_iterations))
        limits = {"newton": config.newton_iterations, "cg": cg_blocks, "search": config.line_search_steps + 1}
        self.limit = dict(limits)
        self._gate = {name: (self._rec(klc.loop_start, 1, self.count[name], self.hit),
                             self._rec(klc.loop_gate, 1, self.hit, self.count[name], limit, self.cond[name]))
                      for name, limit in limits.items()}
        self._extra_begin = self._rec(klc.extra_begin, 1, self.count["newton"], config.newton_iterations, self.running,
                                      self.count["extra"])
        self._extra_next = self._rec(klc.extra_next, 1, self.count["extra"])
        self._extra = {}
        for patient in {0, config.patient_iterations}:
            limit = max(config.penetration_iterations, patient)
            self._extra[patient] = (
                limit,
                self._rec(klc.extra_iteration_worlds, w, self.running, self.count["extra"],
                          config.penetration_iterations, patient, scratch.depth, 0.5 * config.penetration_bound,
                          scratch.patient, scratch.last_dx, scratch.patient_update, scratch.diverged,
                          scratch.solve_worlds, scratch.substep_newton_it, config.newton_iterations,
                          scratch.newton_active),
                self._rec(klc.extra_gate, 1, self.hit, self.count["extra"], limit, self.running, self.cond["extra"]))
        self._any_active = self._any["newton"]

    def _rec(self, kernel, dim, *inputs):
        return wp.launch(kernel, dim=dim, inputs=list(inputs), device=self.device, record_cmd=True)

    def do_while(self, name: str, first, body) -> None:
        """``first()``, then ``body()`` while a world still iterates loop ``name`` ("newton",
        "cg", "search": the scratch's newton_active, cg_active, searching) after the last pass and
        fewer than ``limit[name]`` passes ran."""
        start, gate = self._gate[name]
        any_flag = self._any[name]
        start.launch()
        first()
        any_flag.launch()
        gate.launch()

        def again():
            body()
            any_flag.launch()
            gate.launch()

        self._repeat(name, again, self.limit[name] - 1)

    def extra_iterations(self, depth_launches: list, body, patient_iterations: int) -> None:
        """Newton's extra iterations after the regular ones (all of which must have run): up to
        ``penetration_iterations`` in worlds deeper than half the penetration bound, up to
        ``patient_iterations`` (0 or the config's) in patient worlds not yet converged; stops when
        no world takes one. ``depth_launches``: the recorded launches of the iterate's deepest
        contact per world (``deepest_contact``, and edges')."""
        limit, worlds, gate = self._extra[patient_iterations]
        if limit == 0:
            return

        def choose():
            for cmd in depth_launches:
                cmd.launch()
            worlds.launch()
            self._any_active.launch()
            gate.launch()

        def again():
            body()
            self._extra_next.launch()
            choose()

        self._extra_begin.launch()
        choose()
        self._repeat("extra", again, limit)

    def _repeat(self, name: str, again, passes: int) -> None:
        """``again()`` while ``cond[name]`` holds; without exit tests the condition only runs out
        with the count, so ``again()`` ``passes`` times from Python (no host test of the flag:
        outside a capture ``wp.capture_while`` would read it back on every pass)."""
        if self.check:
            if passes > 0:
                wp.capture_while(self.cond[name], again)
            return
        for _ in range(passes):
            again()
