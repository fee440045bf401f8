"""FEM core, contact: Hertz (sphere against a rigid pad), the Coulomb threshold of a block held
between two pads, and the pad penetration of a stiff object squeezed hard.

Pads are kinematic boxes moved through Control.pad_target_positions; State.pad_positions must be
set to the same start pose before the first step (it starts at the origin).
"""

from __future__ import annotations

import numpy as np
import pytest

from defgrasp_env.sim.materials import Material
from defgrasp_env.sim.meshing import make_object_mesh
from defgrasp_env.sim.model import ContactParams, build_model
from defgrasp_env.sim.solver import ImplicitSolver, SolverConfig
from defgrasp_env.sim.state import Control, State
from fem_meshes import graded_ball_octant

G = 9.81


# --------------------------------------------------------------------------------------------
# 5. Hertz
# --------------------------------------------------------------------------------------------
@pytest.mark.slow
def _pressed_octant(radius: float, e: float, nu: float, y0: float, cells: int, half_x: float = 0.005):
    """A graded ball octant (symmetry planes fixed, no gravity) at height ``y0`` (m) and a
    frictionless pad of half thickness ``half_x`` (m) touching it along x; returns the model,
    state, control and ``pad_at(d)``: the pad centre [1, 3] for an approach ``d`` (m)."""
    mesh = graded_ball_octant(radius, cells=cells, ratio=8.0)
    x0 = mesh.nodes
    fixed = np.zeros((len(x0), 3), bool)
    for axis in range(3):
        fixed[np.abs(x0[:, axis]) < 1e-12, axis] = True
    model = build_model([mesh], [Material(youngs_modulus=e, poisson_ratio=nu)], poses=[((0.0, y0, 0.0), (0, 0, 0, 1))],
                        pad_half_extents=[(half_x, 0.03, 0.03)], contact=ContactParams(pad_friction=0.0),
                        gravity=(0.0, 0.0, 0.0), fixed_axes=[fixed], device="cpu")
    state, control = State.from_model(model), Control.from_model(model)

    def pad_at(d):
        return np.array([[radius + half_x - d, y0, 0.0]], np.float32)

    state.pad_positions.assign(pad_at(0.0))
    return model, state, control, pad_at


def test_hertz_sphere_against_rigid_pad():
    """A ball of radius R = 25 mm squeezed between two rigid frictionless pads, each indenting
    it by d: F = 4/3 E* sqrt(R) d^1.5 with E* = E / (1 - nu^2) (rigid pad).

    By symmetry only the octant x, y, z >= 0 is meshed (graded towards the pole that the pad
    touches: 0.6 mm cells there, ~6 across the contact radius at d/R = 2 %), with roller
    conditions on the three symmetry planes (x = 0 is the mid-plane between the two pads);
    the contact force of the full contact is 4x the pad force of the octant. The pad is moved
    by d in quasi-static increments of 1 % R (each a static Newton solve: dt = 1 s, velocities
    reset), gravity off.

    Tolerance 15 % at d/R = 2..5 %: the mesh is converged to ~2 % (ratio at d/R = 2 %: 1.093,
    1.069, 1.074 with 12, 16, 24 cells per axis), linear tets are slightly stiffer than the
    continuum, and Hertz itself (half-space, small strain) underestimates the force of a finite
    sphere by a few % that grow with d. Measured: F/F_Hertz = 1.07, 1.08, 1.09, 1.10 at
    d/R = 2, 3, 4, 5 %. The log-log slope
    between 2 % and 5 % must be 1.5 +- 0.1 (measured 1.53).
    """
    radius, e, nu = 0.025, 1e6, 0.3
    model, state, control, pad_at = _pressed_octant(radius, e, nu, y0=0.05, cells=16)  # lifted off the ground
    solver = ImplicitSolver(model, SolverConfig(substeps=1, newton_iterations=20, newton_tolerance=2e-8,
                                                cg_iterations=2000, cg_tolerance=1e-4))
    e_star = e / (1.0 - nu ** 2)
    ratios, forces = {}, {}
    for percent in (1, 2, 3, 4, 5):
        d = percent / 100.0 * radius
        control.pad_target_positions.assign(pad_at(d))
        stats = solver.step(state, state, control, dt=1.0)
        state.velocities.zero_()
        assert not stats.diverged.any()
        force = 4.0 * float(state.pad_normal_force.numpy()[0])
        forces[percent] = force
        ratios[percent] = force / (4.0 / 3.0 * e_star * np.sqrt(radius) * d ** 1.5)
        # global equilibrium: the reaction on the mid-plane x = 0 balances the pad force
        on_mid_plane = model.free_axes.numpy()[:, 0] == 0.0  # x prescribed: the symmetry plane x = 0
        support = -state.elastic_force.numpy()[on_mid_plane, 0].sum()
        assert 4.0 * support == pytest.approx(force, rel=0.01)
    for percent in (2, 3, 4, 5):
        assert ratios[percent] == pytest.approx(1.0, abs=0.15), ratios
    slope = np.log(forces[5] / forces[2]) / np.log(5.0 / 2.0)
    assert slope == pytest.approx(1.5, abs=0.1), slope


@pytest.mark.slow
@pytest.mark.parametrize("radius", [0.015, 0.03])
@pytest.mark.parametrize("e", [1e4, 1e5])
def test_hertz_soft_sphere_default_settings(e, radius):
    """Soft balls with the DEFAULT contact and solver settings (only the pads frictionless, as
    Hertz assumes), at the 0.6 m goal height: F / F_Hertz within 15 % at approaches of 0.5, 1, 2
    and 4 % of R (the octant set-up of test_hertz_sphere_against_rigid_pad, 12 cells per axis:
    ~9 % stiffer than Hertz from the mesh alone). The material-scaled penalty stiffness was set
    on R = 20 mm; these radii were not tuned on. Each approach is 3 quasi-static steps (dt = 1 s,
    velocities reset). Before (fixed 1e6 N/m): 14x Hertz at 0.5 % and 2.6x at 4 % for E = 1e4."""
    nu = 0.3
    model, state, control, pad_at = _pressed_octant(radius, e, nu, y0=0.6, cells=12)
    solver = ImplicitSolver(model, SolverConfig())
    e_star = e / (1.0 - nu ** 2)
    ratios = {}
    for percent in (0.5, 1, 2, 4):
        d = percent / 100.0 * radius
        control.pad_target_positions.assign(pad_at(d))
        for _ in range(3):
            assert not solver.step(state, state, control, dt=1.0).diverged.any()
            state.velocities.zero_()
        force = 4.0 * float(state.pad_normal_force.numpy()[0])
        ratios[percent] = force / (4.0 / 3.0 * e_star * np.sqrt(radius) * d ** 1.5)
    assert all(abs(r - 1.0) <= 0.15 for r in ratios.values()), ratios


# --------------------------------------------------------------------------------------------
# 6. Coulomb threshold
# --------------------------------------------------------------------------------------------
# Newton must resolve the friction law: its smoothing width is eps = stick_velocity * h = 2.5 um
# per substep (h = 25 ms), so the update tolerance must be well below it. The default
# SolverConfig (1e-5 m, 4 iterations) holds the block ~10-13 % beyond the Coulomb limit
# (measured onsets 0.90 N* for mu = 0.5, 0.87 N* for mu = 1): see the report in RESULTS.md.
FRICTION_CONFIG = SolverConfig(newton_iterations=8, newton_tolerance=1e-7)
BLOCK_PAD_HALF = np.array([0.005, 0.015, 0.015])


def squeeze_lift_open(mu: float, compression: float, opening_rate: float):
    """A 40 mm cube (E = 1e5) on the ground (default contact parameters) is squeezed by two pads
    (x = -+) to ``compression``
    (m per side), lifted 20 mm (cosine profile over 1 s, peak acceleration 1 % g), held 1.25 s,
    then the pads open at ``opening_rate`` (m/s per side) until the block slides (downward speed
    relative to the pads > 2 x stick_velocity), then stay there 0.5 s.

    Returns per-step rows (t, mean pad normal force N, block centroid y - pad y, block vy) and
    the indices of the hold window and of the onset step."""
    mesh = make_object_mesh("cuboid")
    model = build_model([mesh], [Material(density=1000.0, youngs_modulus=1e5, poisson_ratio=0.3)],
                        pad_half_extents=[BLOCK_PAD_HALF, BLOCK_PAD_HALF],
                        contact=ContactParams(pad_friction=mu), device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    solver = ImplicitSolver(model, FRICTION_CONFIG)
    mass = model.node_mass.numpy().astype(np.float64)
    stick = model.contact.stick_velocity
    dt = 0.05

    def pads(c, lift):
        x = 0.02 + BLOCK_PAD_HALF[0] - c
        return np.array([[-x, 0.02 + lift, 0.0], [x, 0.02 + lift, 0.0]], np.float32)

    state.pad_positions.assign(pads(0.0, 0.0))
    plan = [pads(compression * (k + 1) / 5, 0.0) for k in range(5)] + [pads(compression, 0.0)] * 5
    plan += [pads(compression, 0.01 * (1.0 - np.cos(np.pi * (k + 1) / 20))) for k in range(20)]
    hold = (len(plan) + 5, len(plan) + 25)       # 0.25 s settling, then 1 s
    plan += [pads(compression, 0.02)] * 25
    rows, onset, c = [], None, compression
    for k in range(2000):
        if k < len(plan):
            target = plan[k]
        elif onset is None:
            c = max(c - opening_rate * dt, 0.0)
            target = pads(c, 0.02)
        target_y = float(target[0, 1])
        control.pad_target_positions.assign(target)
        stats = solver.step(state, state, control, dt)
        assert not stats.diverged.any()
        vy = float(mass @ state.velocities.numpy()[:, 1] / mass.sum())
        y = float(mass @ state.positions.numpy()[:, 1] / mass.sum())
        rows.append((k * dt + dt, float(state.pad_normal_force.numpy().mean()), y - target_y, vy))
        if onset is None and k >= len(plan) and vy < -2.0 * stick:
            onset = k
        if onset is not None and k >= onset + 10:
            break
    assert onset is not None, "the block never slid"
    return np.array(rows), hold, onset, mass.sum() * G, stick, state


@pytest.mark.parametrize("mu", [0.5, 1.0])
def test_coulomb_hold_and_slip_threshold(mu):
    """Held with 2 mu N > m g, slides with 2 mu N < m g, and the squeeze force at the onset of
    sliding equals m g / (2 mu) within 10 %.

    Truth: Coulomb friction on the two pad contacts. The law is smoothed (IPC-style) below the
    slip speed stick_velocity = 0.1 mm/s, where the friction is mu N (2 s/e - (s/e)^2): a held
    block creeps at v_s (1 - sqrt(1 - phi)) < v_s for a load fraction phi = m g / (2 mu N), so
    over 1 s of holding the creep must stay below v_s * 1 s = 0.1 mm (and match the formula
    within 5 %; measured 0.1 % and 1 %: N drifts slightly); in the sliding regime (speed > v_s) it is
    exactly mu N. The onset is taken where the block's speed first exceeds 2 v_s while the pads
    open slowly (N falls ~1 % of m g/(2 mu) per step): measured N/N* = 0.95 (mu = 0.5 and 1,
    default contact parameters; 0.93 - 0.97 with the former 1e6 N/m penalty), i.e. the onset is
    found within 5-7 %. Below the threshold the block must slide: it accelerates to > 10 v_s and
    moves > 1 mm within the 10 steps after the onset. It need not keep sliding to the end of that
    window: at mu = 0.5 the uncompressed rim of the block above the pads (it stands 0.2 mm proud
    of the pad face) reaches the pads' top edges after ~5 mm and catches there (node-vs-box
    contact at a sharp edge, not Coulomb friction), and at mu = 1 the block lands on the ground
    after 20 mm.
    """
    compression = {0.5: 2e-4, 1.0: 1.2e-4}[mu]
    rows, (h0, h1), onset, weight, stick, state = squeeze_lift_open(mu, compression, opening_rate=2e-5)
    n_star = weight / (2.0 * mu)
    # held: lifted with the pads, creeping less than the stick speed allows
    n_hold = rows[h0:h1, 1].mean()
    assert n_hold > 1.5 * n_star
    creep = rows[h0, 2] - rows[h1, 2]
    assert 0.0 <= creep < stick * 1.0, creep
    phi = n_star / n_hold
    assert creep == pytest.approx(stick * (1.0 - np.sqrt(1.0 - phi)) * 1.0, rel=0.05)
    assert rows[h1, 2] > -0.001                       # still at the lift height (sag < 1 mm)
    # threshold: the squeeze force where it starts to slide
    n_onset = 0.5 * (rows[onset, 1] + rows[onset - 1, 1])
    assert n_onset == pytest.approx(n_star, rel=0.10), (n_onset / n_star)
    # below the threshold (pads stopped at the onset gap, 2 mu N < m g) it keeps sliding down: it
    # slides on by > 1 mm at > 10 x the stick speed (the Newton solves after the onset stop at the
    # iteration limit, so the path can differ with the linear solver: it may land on the ground,
    # 20 mm down, within the 0.5 s)
    assert rows[-1, 2] < rows[onset, 2] - 0.001
    assert rows[onset:, 3].min() < -10.0 * stick


# --------------------------------------------------------------------------------------------
# 8. penetration into the pads of a stiff object squeezed hard
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["cuboid", "sphere", "cylinder"])
def test_pad_penetration_below_1mm_at_100N(name):
    """E = 1e7, pads (8 x 37.5 x 22 mm, like the gripper's) close on the object at 20 Hz with the
    default SolverConfig until each pushes with >= 100 N; every node's depth inside a pad box
    (computed here from the returned positions) and SolveStats.penetration stay < 1 mm.
    Penetration is force / stiffness per node (1e6 N/m): 100 N on a single node would be 0.1 mm.
    """
    mesh = make_object_mesh(name)
    half = np.array([0.004, 0.01875, 0.011])
    model = build_model([mesh], [Material(youngs_modulus=1e7)], pad_half_extents=[half, half], device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    solver = ImplicitSolver(model, SolverConfig())
    x0 = mesh.nodes
    width = x0[:, 0].max()
    centre_y = 0.5 * (x0[:, 1].min() + x0[:, 1].max())

    def pads(c):
        x = width + half[0] - c
        return np.array([[-x, centre_y, 0.0], [x, centre_y, 0.0]], np.float32)

    state.pad_positions.assign(pads(0.0))
    c, force, deepest = 0.0, 0.0, 0.0
    for _ in range(60):
        if force < 120.0:
            c += 5e-5                      # 1 mm/s per side
        control.pad_target_positions.assign(pads(c))
        stats = solver.step(state, state, control, dt=0.05)
        assert not stats.diverged.any()
        force = float(state.pad_normal_force.numpy().min())
        x = state.positions.numpy().astype(np.float64)
        for p in state.pad_positions.numpy().astype(np.float64):
            local = np.abs(x - p)
            inside = np.all(local < half, axis=1)
            if inside.any():
                deepest = max(deepest, float(np.max(np.min(half - local[inside], axis=1))))
        assert stats.penetration[0] < 1e-3
        assert np.all(np.isfinite(x))
    assert force >= 100.0, force
    assert deepest < 1e-3, deepest


# --------------------------------------------------------------------------------------------
# 9. a held object turned by the pads: Newton converges within the default iterations
# --------------------------------------------------------------------------------------------
def test_block_turned_by_the_pads_converges_each_step():
    """A 40 mm cube (E = 1e5) squeezed 2 mm per side between two pads that then turn together
    about the vertical axis (3 deg per 50 ms step) while lifting 1 mm per step: with the default
    SolverConfig every step after the first two of the turn (the start from rest needs more than
    4 Newton iterations to settle the stick-slip law) ends converged (largest update of its last
    Newton step below newton_tolerance), and the block turns with the pads (mean node yaw within
    1 deg of theirs: the contacts stick, mu = 1).

    The failure this guards against: with the plain start guess x + h v, nodes of the squeezed
    faces begin micrometres outside a turned pad; with no contact stiffness there, Newton sends them
    millimetres into the pad and the line search cuts the world's step to ~1 %. Measured here: with
    that guess 0 of these 18 steps converged (last update 3.1-4.0 mm); with the pad-depth guess
    (kernels/contact.py keep_pad_depth) all 18 did (8e-7 m), in 2 Newton iterations per substep."""
    mesh = make_object_mesh("cuboid")
    model = build_model([mesh], [Material(youngs_modulus=1e5)], pad_half_extents=[BLOCK_PAD_HALF, BLOCK_PAD_HALF],
                        device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    config = SolverConfig()
    solver = ImplicitSolver(model, config)

    def pads(c, yaw, lift):
        x = 0.02 + BLOCK_PAD_HALF[0] - c
        turn = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
        pos = np.array([[-x, 0, 0], [x, 0, 0]]) @ turn.T + [0.0, 0.02 + lift, 0.0]
        quat = np.tile([0.0, np.sin(yaw / 2), 0.0, np.cos(yaw / 2)], (2, 1))
        return pos.astype(np.float32), quat.astype(np.float32)

    pos, quat = pads(0.0, 0.0, 0.0)
    state.pad_positions.assign(pos)
    state.pad_orientations.assign(quat)
    plan = [(2e-3 * (k + 1) / 5, 0.0, 0.0) for k in range(5)] + [(2e-3, 0.0, 0.0)] * 3
    turning = [(2e-3, np.radians(3.0) * (k + 1), 1e-3 * (k + 1)) for k in range(20)]
    rest = state.positions.numpy().astype(np.float64)
    for k, (c, yaw, lift) in enumerate(plan + turning):
        pos, quat = pads(c, yaw, lift)
        control.pad_target_positions.assign(pos)
        control.pad_target_orientations.assign(quat)
        stats = solver.step(state, state, control, dt=0.05)
        assert not stats.diverged.any()
        if k >= len(plan) + 2:  # after the start of the turn (rest -> 1 mm per step at the contacts)
            assert stats.last_update[0] <= config.newton_tolerance, (k, stats.last_update[0])
    x = state.positions.numpy().astype(np.float64)
    d0, d1 = rest[:, [0, 2]] - rest[:, [0, 2]].mean(0), x[:, [0, 2]] - x[:, [0, 2]].mean(0)
    node_yaw = np.arctan2(d0[:, 0] * d1[:, 1] - d0[:, 1] * d1[:, 0], (d0 * d1).sum(1))  # about +y: z -> x
    far = np.linalg.norm(d0, axis=1) > 0.01
    assert np.degrees(-node_yaw[far].mean()) == pytest.approx(60.0, abs=1.0)
