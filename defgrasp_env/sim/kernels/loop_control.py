"""Device-side control flow of the solver's loops: whether any world is still iterating, loop
counters and the gate of Newton's extra iterations, as one-element int32 flags that
``wp.capture_while`` tests (a conditional node of a CUDA graph, a loop of a Warp CPU graph, or a
host test when nothing is captured), so a whole substep needs no host round trip.

A loop is a do-while: ``body``, ``flag_any`` (any world's flag set -> ``hit``), ``loop_gate``
(count the pass; ``cond`` = hit and count < limit). ``loop_start`` resets the count.
"""

from __future__ import annotations

import warp as wp

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.kernel
def flag_any(flags: wp.array(dtype=int), hit: wp.array(dtype=wp.int32)):
    """hit[0] = 1 where any flags[w] != 0 (every writer writes 1; ``hit`` is cleared by the gate)."""
    w = wp.tid()
    if flags[w] != 0:
        hit[0] = wp.int32(1)


@wp.kernel
def set_hit(hit: wp.array(dtype=wp.int32)):
    """hit[0] = 1: the "any world still iterating" test of a loop run without exit tests."""
    hit[0] = wp.int32(1)


@wp.kernel
def loop_start(count: wp.array(dtype=wp.int32), hit: wp.array(dtype=wp.int32)):
    count[0] = wp.int32(0)
    hit[0] = wp.int32(0)


@wp.kernel
def loop_gate(hit: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32), limit: int,
              cond: wp.array(dtype=wp.int32)):
    """After a pass of a loop body: count it; go on while a world is still iterating and fewer than
    ``limit`` passes ran; clear ``hit`` for the next pass."""
    c = count[0] + wp.int32(1)
    count[0] = c
    go = wp.int32(0)
    if hit[0] != 0 and c < wp.int32(limit):
        go = wp.int32(1)
    cond[0] = go
    hit[0] = wp.int32(0)


@wp.kernel
def extra_begin(regular_count: wp.array(dtype=wp.int32), regular: int, running: wp.array(dtype=wp.int32),
                extra_count: wp.array(dtype=wp.int32)):
    """Newton's extra iterations run only after all ``regular`` iterations ran (the regular loop did
    not stop early because every world had converged; per world, ``extra_iteration_worlds``)."""
    go = wp.int32(0)
    if regular_count[0] == wp.int32(regular):
        go = wp.int32(1)
    running[0] = go
    extra_count[0] = wp.int32(0)


@wp.kernel
def extra_iteration_worlds(running: wp.array(dtype=wp.int32), extra_count: wp.array(dtype=wp.int32),
                           deep_iterations: int, patient_iterations: int, depth: wp.array(dtype=float),
                           bound: float, patient: wp.array(dtype=int), last_dx: wp.array(dtype=float),
                           patient_update: wp.array(dtype=float),
                           diverged: wp.array(dtype=int), solve: wp.array(dtype=int),
                           substep_iterations: wp.array(dtype=int), regular: int,
                           newton_active: wp.array(dtype=int)):
    """Which worlds take extra Newton iteration e (= ``extra_count``): in the first
    ``deep_iterations``, those whose iterate is deeper than ``bound`` (m; ``depth`` from
    ``deepest_contact``, cleared here); in the first ``patient_iterations``, also the ``patient``
    worlds whose last update (m) is above their ``patient_update`` (m) and that did not diverge; no other world: only
    worlds of this solve (``solve``) that ran all ``regular`` iterations themselves (a world that
    converged earlier takes none, whatever the other worlds did: each world's result is the one
    it gets alone)."""
    w = wp.tid()
    d = depth[w]
    depth[w] = 0.0
    if running[0] == 0:
        return
    if solve[w] == 0 or substep_iterations[w] < wp.int32(regular):
        newton_active[w] = 0
        return
    e = extra_count[0]
    active = 0
    if e < wp.int32(deep_iterations) and d > bound:
        active = 1
    if e < wp.int32(patient_iterations) and patient[w] != 0 and last_dx[w] > patient_update[w] and diverged[w] == 0:
        active = 1
    newton_active[w] = active


@wp.kernel
def extra_gate(hit: wp.array(dtype=wp.int32), extra_count: wp.array(dtype=wp.int32), limit: int,
               running: wp.array(dtype=wp.int32), cond: wp.array(dtype=wp.int32)):
    """Before extra iteration e: take it while running, a world is active and e < ``limit``;
    otherwise stop for good (``running`` = 0)."""
    go = wp.int32(0)
    if running[0] != 0 and hit[0] != 0 and extra_count[0] < wp.int32(limit):
        go = wp.int32(1)
    cond[0] = go
    running[0] = go
    hit[0] = wp.int32(0)


@wp.kernel
def extra_next(extra_count: wp.array(dtype=wp.int32)):
    extra_count[0] = extra_count[0] + wp.int32(1)
