"""The actuator force limit's decisions of a substep on the device, for a control period captured
as one graph (``period_graph.PeriodGraph``): the device twins of the host's rules, world by world
in float64 with the same operations, so that on the CPU the graph's results are the host's bit for
bit: the patient re-solve (``limit_loads.SolveLoads.patient_re_solve`` as the scene's
``_patient_if_over`` applies it), the retries with less motion and the back-off of a stopped world
that still reads over (``wrist.force_limit.limited_substep``: Illinois regula falsi on the measured
load).

Per world the limit's state lives in [W] float64 arrays (``LimitState``); what the graph's
conditional nodes test is counted into the int32 ``gate`` (``GATE_*``) and turned into one-element
conditions by single-thread kernels. Kernels take arrays and scalars only."""

from __future__ import annotations

import warp as wp

from .scene_kernels import solve_load_row

# forward only: nothing differentiates these kernels
wp.set_module_options({"enable_backward": False})

#: the entries of a period graph's ``gate``: open (the period's substeps go on on the device), the
#: substep run last, the solves after the first tries and the worlds they solved, and the counts a
#: decision in progress gathers (patient worlds, non-finite worlds, worlds whose motion changed,
#: worlds over the limit, worlds searching, worlds whose trial is not their scale, retries run,
#: whether the limit's final solve is still to run)
(GATE_OPEN, GATE_SUBSTEP, GATE_SOLVES, GATE_WORLD_SOLVES, GATE_PATIENT, GATE_NONFINITE, GATE_CHANGED, GATE_OVER,
 GATE_SEARCHING, GATE_UNEQUAL, GATE_RETRIES, GATE_FINAL) = (wp.constant(i) for i in range(12))
GATE_SIZE = 12


@wp.kernel
def open_period_gate(gate: wp.array(dtype=wp.int32)):
    """``gate`` open, every count 0, at the start of a control period's graph."""
    for i in range(GATE_SIZE):
        gate[i] = 0
    gate[GATE_OPEN] = 1


@wp.kernel
def mark_substep(k: int, gate: wp.array(dtype=wp.int32)):
    """Substep ``k`` is the one the graph runs now."""
    gate[GATE_SUBSTEP] = k


@wp.kernel
def choose_patient(loads: wp.array(dtype=solve_load_row), fraction: wp.array(dtype=wp.float64),
                   patient_solved: wp.array(dtype=wp.int32), first: int, unconverged: wp.array(dtype=int),
                   diverged: wp.array(dtype=int), tolerance: wp.float64, update_fraction: wp.float64,
                   newton_tolerance: wp.float64, patient: wp.array(dtype=int), patient_update: wp.array(dtype=float),
                   gate: wp.array(dtype=wp.int32)):
    """The patient re-solve after a solve of ``fraction`` [W] of the planned motion, as the host
    chooses it (``SolveLoads.patient_re_solve`` among the worlds whose solve did not converge or
    diverged and whose last solve was not patient already, ``patient_solved``; ``first``: the
    substep's first try, which clears those marks): world w is patient where its load
    (``loads[w][2]``) is over 1 + ``tolerance``, unless it moved and reads over even less twice
    its error; its update target is ``update_fraction`` x its deciding update where it moved, 0
    where not, at least ``newton_tolerance`` (as ``ImplicitSolver.advance`` stores it); a world
    with non-finite pad forces never (``count_nonfinite`` stops the substep). Writes the solver's
    ``patient`` and ``patient_update``; counts the patient worlds into ``gate``."""
    w = wp.tid()
    if first != 0:
        patient_solved[w] = 0
    row = loads[w]
    limit = wp.float64(1.0) + tolerance
    moved = fraction[w] != wp.float64(0.0)
    p = int(0)
    if row[3] == wp.float64(1.0) and row[2] > limit and (unconverged[w] != 0 or diverged[w] != 0) \
            and patient_solved[w] == 0:
        error = row[4]
        certainly = wp.isfinite(error) and row[2] - wp.float64(2.0) * error > limit
        if not (certainly and moved):
            p = 1
            wp.atomic_add(gate, GATE_PATIENT, 1)
    target = wp.float64(0.0)
    if moved:
        target = update_fraction * row[5]
    patient[w] = p
    patient_update[w] = wp.float32(wp.max(target, newton_tolerance))


@wp.kernel
def count_nonfinite(loads: wp.array(dtype=solve_load_row), gate: wp.array(dtype=wp.int32)):
    """Counts into ``gate`` the worlds whose solve left non-finite pad forces (``loads[w][3]`` not
    1), where the host raises (``SolveLoads.from_rows``): launched after every solve's loads, the
    count stays until the period's next open, and every later decision stands still on it."""
    if loads[wp.tid()][3] != wp.float64(1.0):
        wp.atomic_add(gate, GATE_NONFINITE, 1)


@wp.kernel
def patient_gate(gate: wp.array(dtype=wp.int32), cond: wp.array(dtype=wp.int32)):
    """``cond[0]`` = 1 where the last ``choose_patient`` found patient worlds and no solve of the
    period left non-finite pad forces (the host raises there): the graph re-solves them, counted as
    a solve of that many worlds."""
    go = wp.int32(0)
    if gate[GATE_PATIENT] > 0 and gate[GATE_NONFINITE] == 0:
        go = wp.int32(1)
        gate[GATE_SOLVES] = gate[GATE_SOLVES] + 1
        gate[GATE_WORLD_SOLVES] = gate[GATE_WORLD_SOLVES] + gate[GATE_PATIENT]
    gate[GATE_PATIENT] = 0
    cond[0] = go


@wp.kernel
def begin_patient_solve(patient: wp.array(dtype=int), solve_worlds: wp.array(dtype=int)):
    """A patient re-solve solves the patient worlds only (``advance(worlds=patient)``)."""
    w = wp.tid()
    solve_worlds[w] = patient[w]


@wp.kernel
def end_patient_solve(patient: wp.array(dtype=int), patient_solved: wp.array(dtype=wp.int32),
                      solve_worlds: wp.array(dtype=int)):
    """After a patient re-solve (or where none ran): its worlds' last solve was patient, no world
    is patient any more, every world is solved by the next solve (as ``advance`` leaves them)."""
    w = wp.tid()
    if patient[w] != 0:
        patient_solved[w] = 1
    patient[w] = 0
    solve_worlds[w] = 1


@wp.func
def regula_falsi(lo: wp.float64, hi: wp.float64, f_lo: wp.float64, f_hi: wp.float64, limit: wp.float64):
    """``wrist.force_limit.next_scale``: the fraction in (lo, hi) where the load, linear between
    (lo, f_lo) and (hi, f_hi), reaches ``limit``, 10 % of the bracket away from either end."""
    span = f_hi - f_lo
    frac = (limit - f_lo) / wp.where(span < wp.float64(1e-12), wp.float64(1e-12), span)  # NaN stays, as in numpy
    frac = wp.where(frac < wp.float64(0.1), wp.float64(0.1), wp.where(frac > wp.float64(0.9), wp.float64(0.9), frac))
    return lo + (hi - lo) * frac


@wp.struct
class LimitState:
    """The force limit's state of a substep per world (``limited_substep``'s arrays), [W] each:
    the accepted fraction ``scale``, the bracket ``lo`` / ``hi`` with its loads ``f_lo`` /
    ``f_hi``, the Illinois ``side`` (-1, 0, 1), the fraction of the last ``trial`` and of the
    world's last solve (``solved``), float64; ``searching`` (int32: still bracketing)."""

    scale: wp.array(dtype=wp.float64)
    lo: wp.array(dtype=wp.float64)
    hi: wp.array(dtype=wp.float64)
    f_lo: wp.array(dtype=wp.float64)
    f_hi: wp.array(dtype=wp.float64)
    side: wp.array(dtype=wp.float64)
    trial: wp.array(dtype=wp.float64)
    solved: wp.array(dtype=wp.float64)
    searching: wp.array(dtype=wp.int32)


@wp.kernel
def limit_begin(loads: wp.array(dtype=solve_load_row), fraction: wp.array(dtype=wp.float64), tolerance: wp.float64,
                s: LimitState, gate: wp.array(dtype=wp.int32)):
    """``limited_substep`` after the first try (of ``fraction``, its loads after the patient
    re-solve): a world that moved and is over 1 + ``tolerance`` stops (scale 0) and, where its
    load at the substep start (``loads[w][0]``) was under 1, brackets [0, its fraction]; counts
    the worlds over and searching into ``gate``."""
    w = wp.tid()
    row = loads[w]
    f = fraction[w]
    s.solved[w] = f
    s.searching[w] = 0
    s.scale[w] = f
    if row[2] > wp.float64(1.0) * (wp.float64(1.0) + tolerance) and f > wp.float64(0.0):
        s.lo[w] = wp.float64(0.0)
        s.f_lo[w] = wp.where(row[0] > wp.float64(1.0), wp.float64(1.0), row[0])  # np.minimum: NaN stays
        s.hi[w] = f
        s.f_hi[w] = row[2]
        s.side[w] = wp.float64(0.0)
        s.scale[w] = wp.float64(0.0)
        wp.atomic_add(gate, GATE_OVER, 1)
        if row[0] < wp.float64(1.0):
            s.searching[w] = 1
            wp.atomic_add(gate, GATE_SEARCHING, 1)


@wp.kernel
def back_off_begin(loads: wp.array(dtype=solve_load_row), aimed: wp.array(dtype=wp.vec3d), tolerance: wp.float64,
                   back_off: wp.float64, s: LimitState, gate: wp.array(dtype=wp.int32)):
    """``limited_substep`` after the stop (the accepted solve of the first try or of the retries,
    its loads): a world stopped or held (scale at most 0) whose load is still over 1 + ``tolerance``
    and whose wrist can back off (``aimed[w]``, ``Gripper.aim_back_off``, not zero: the scene's
    ``_aim_back_off``) backs off: it brackets [-``back_off``, 0] (no load assumed at the far end),
    its scale the stop until a back-off reads within the limit; counts those worlds into ``gate``
    as over and searching."""
    w = wp.tid()
    row = loads[w]
    s.searching[w] = 0
    a = aimed[w]
    can = a[0] != wp.float64(0.0) or a[1] != wp.float64(0.0) or a[2] != wp.float64(0.0)
    if s.scale[w] <= wp.float64(0.0) and row[2] > wp.float64(1.0) * (wp.float64(1.0) + tolerance) and can:
        s.lo[w] = -back_off
        s.f_lo[w] = wp.float64(0.0)
        s.hi[w] = s.scale[w]
        s.f_hi[w] = row[2]
        s.side[w] = wp.float64(0.0)
        s.searching[w] = 1
        wp.atomic_add(gate, GATE_OVER, 1)
        wp.atomic_add(gate, GATE_SEARCHING, 1)


@wp.kernel
def limit_gate(gate: wp.array(dtype=wp.int32), limiting: wp.array(dtype=wp.int32), retry: wp.array(dtype=wp.int32),
               final: wp.array(dtype=wp.int32)):
    """After ``limit_begin`` (or ``back_off_begin``): the limit acts where a world is over
    (``limiting``; not after a non-finite solve), retries while one searches (``retry``), and ends
    with a solve of the scales unless a retry is accepted as is (``final``)."""
    go = wp.int32(0)
    again = wp.int32(0)
    if gate[GATE_OVER] > 0 and gate[GATE_NONFINITE] == 0:
        go = wp.int32(1)
        if gate[GATE_SEARCHING] > 0:
            again = wp.int32(1)
    limiting[0] = go
    retry[0] = again
    final[0] = go
    gate[GATE_OVER] = 0
    gate[GATE_SEARCHING] = 0
    gate[GATE_RETRIES] = 0


@wp.kernel
def limit_trial(use_scale: int, s: LimitState, fraction: wp.array(dtype=wp.float64),
                solve_worlds: wp.array(dtype=int), patient_solved: wp.array(dtype=wp.int32),
                gate: wp.array(dtype=wp.int32)):
    """The next solve's fraction per world: the regula falsi point of a searching world's bracket,
    the scale elsewhere (``use_scale``: the scale everywhere, the final solve); written to the
    gripper's ``fraction``; only the worlds whose fraction changed since their last solve are
    solved (``solve_worlds``, counted into ``gate``), and theirs is then not a patient one."""
    w = wp.tid()
    t = s.scale[w]
    if use_scale == 0 and s.searching[w] != 0:
        t = regula_falsi(s.lo[w], s.hi[w], s.f_lo[w], s.f_hi[w], wp.float64(1.0))
    s.trial[w] = t
    fraction[w] = t
    changed = int(0)
    if t != s.solved[w]:
        changed = 1
        patient_solved[w] = 0
        wp.atomic_add(gate, GATE_CHANGED, 1)
    solve_worlds[w] = changed
    s.solved[w] = t


@wp.kernel
def solve_gate(gate: wp.array(dtype=wp.int32), cond: wp.array(dtype=wp.int32)):
    """A limit's solve (counted, also with no world to solve: the host counts it so) solves the
    worlds ``limit_trial`` changed: ``cond[0]`` = 1 where there are any (and no solve of the
    period left non-finite pad forces)."""
    n = gate[GATE_CHANGED]
    gate[GATE_SOLVES] = gate[GATE_SOLVES] + 1
    gate[GATE_WORLD_SOLVES] = gate[GATE_WORLD_SOLVES] + n
    gate[GATE_CHANGED] = 0
    go = wp.int32(0)
    if n > 0 and gate[GATE_NONFINITE] == 0:
        go = wp.int32(1)
    cond[0] = go


@wp.kernel
def select_all_worlds(solve_worlds: wp.array(dtype=int)):
    """Every world is solved by the next solve."""
    solve_worlds[wp.tid()] = 1


@wp.kernel
def limit_update(loads: wp.array(dtype=solve_load_row), tolerance: wp.float64, s: LimitState,
                 gate: wp.array(dtype=wp.int32)):
    """``limited_substep``'s bracket update after a retry: a searching world whose trial read at
    most 1 + ``tolerance`` keeps it as its low end and its scale (done from 1 - ``tolerance`` up),
    else as its high end, with the Illinois halving of a stale end; counts into ``gate``
    the worlds whose trial is not their scale and those still searching."""
    w = wp.tid()
    one = wp.float64(1.0)
    if s.searching[w] != 0:
        load = loads[w][2]
        t = s.trial[w]
        side = s.side[w]
        low = load <= one * (one + tolerance)
        done = low and load >= one * (one - tolerance)
        if low:
            if side < wp.float64(0.0):
                s.f_hi[w] = one + wp.float64(0.5) * (s.f_hi[w] - one)
            s.lo[w] = t
            s.f_lo[w] = load
            s.side[w] = wp.float64(-1.0)
        else:
            if side > wp.float64(0.0):
                s.f_lo[w] = one - wp.float64(0.5) * (one - s.f_lo[w])
            s.hi[w] = t
            s.f_hi[w] = load
            s.side[w] = wp.float64(1.0)
        if low:
            s.scale[w] = t
        if done:
            s.searching[w] = 0
    if s.trial[w] != s.scale[w]:
        wp.atomic_add(gate, GATE_UNEQUAL, 1)
    if s.searching[w] != 0:
        wp.atomic_add(gate, GATE_SEARCHING, 1)


@wp.kernel
def retry_gate(retries: int, gate: wp.array(dtype=wp.int32), retry: wp.array(dtype=wp.int32),
               final: wp.array(dtype=wp.int32)):
    """After a retry's update: retry again while fewer than ``retries`` ran and a world searches
    (``_bracket``: a world's search ends by its own test only, never because every world's trial
    was accepted); then accepted as is where every world's trial is its scale (no final solve; nor
    after a non-finite solve: the host raises)."""
    gate[GATE_RETRIES] = gate[GATE_RETRIES] + 1
    if gate[GATE_NONFINITE] != 0:
        final[0] = 0
        retry[0] = 0
    elif gate[GATE_RETRIES] < retries and gate[GATE_SEARCHING] > 0:
        retry[0] = 1
    else:
        retry[0] = 0
        if gate[GATE_UNEQUAL] == 0:
            final[0] = 0
    gate[GATE_UNEQUAL] = 0
    gate[GATE_SEARCHING] = 0


@wp.kernel
def close_gate_if_nonfinite(gate: wp.array(dtype=wp.int32)):
    """``gate`` closed where a solve of the substep left non-finite pad forces (``count_nonfinite``):
    the period stops there and the host raises (``SolveLoads.from_rows`` on the last loads)."""
    if gate[GATE_NONFINITE] != 0:
        gate[GATE_OPEN] = 0
