"""A control period as one graph (``period_graph.PeriodGraph``): the scene's substeps replayed on
the device with the actuator force limit's decisions (patient re-solves, retries with less
motion) taken there by the host's rules (``limit_kernels``). The reference is the same scene
stepping every substep from the host (``period_graphs = False``): the same kernels and decisions
in the same order, so on the CPU every output must be equal bit for bit; the decision kernels are
also checked one by one against the host's functions."""

from __future__ import annotations

import dataclasses
import functools

import gymnasium as gym
import numpy as np
import pytest
import warp as wp

import defgrasp_env  # noqa: F401
from defgrasp_env.envs.config import PickupConfig
from defgrasp_env.envs import limit_kernels as lk
from defgrasp_env.envs.scene_kernels import solve_load_row
from defgrasp_env.wrist.force_limit import FORCE_TOLERANCE
from contact_rollout import ExpertNoisyPress


def _run(period_graphs: bool, substeps: int, steps: int, device: str = "cpu", modulus: float = 1e6):
    """W = 3 cuboid worlds (E = 1e6 by default): the expert, the expert with noise, and a world closing over
    the object and pressing it into the ground at full speed (its wrist at the force limit: first
    tries over the limit, retries, patient re-solves). Returns every output array (also the world-solves
    beyond one per world and substep, per step) and the number of substeps each step's graph accepted."""
    solver = dataclasses.replace(PickupConfig().solver, substeps=substeps)
    env = gym.make_vec("DeformablePickup-v0", num_envs=3, vectorization_mode="vector_entry_point", object="cuboid",
                       youngs_modulus=modulus, solver=solver, device=device)
    obs, _ = env.reset(seed=3)
    scene = env.unwrapped.scene
    scene.period_graphs = period_graphs
    policy = ExpertNoisyPress(env)
    out, graphed, extra = {}, [], []
    for k in range(steps):
        before, solves = scene.device_substeps, scene.world_solves
        obs, reward, terminated, truncated, info = env.step(policy.actions(obs))
        graphed.append(scene.device_substeps - before)
        extra.append(scene.world_solves - solves - scene.substeps * 3)
        assert not scene.solver.scratch.patient.numpy().any()  # no patient mark outlives its solve
        out.update({f"{k}/obs/{name}": np.asarray(v) for name, v in obs.items()})
        out[f"{k}/reward"] = np.asarray(reward)
        out.update({f"{k}/info/{name}": np.asarray(v) for name, v in info.items()})
        g = scene.gripper  # its host readers (teleop, viewers, scripted controllers read these)
        out.update({f"{k}/gripper/{name}": np.array(v) for name, v in
                    (("q", g.q), ("gap", g.gap), ("tip_force", g.tip_force), ("pad_force", g.pad_force),
                     ("grip_stiffness", g.grip_stiffness), ("held", g.held_at_limit()[1]))})
    for name in ("positions", "velocities", "elastic_force", "contact_force", "von_mises", "pad_normal_force",
                 "pad_force"):
        out[f"state/{name}"] = getattr(scene.state, name).numpy().copy()
    out["world_solves"] = np.array(scene.world_solves)
    out["extra_world_solves"] = np.array(extra)
    env.close()
    return out, np.array(graphed), scene.substeps


@pytest.mark.parametrize("substeps", [4, 5])
def test_a_period_on_the_device_gives_the_bits_of_substeps_from_the_host(substeps):
    """Bit for bit on the CPU, with 4 substeps (the env's) and 5 (odd: the period ends with a copy
    back into the home state), stiff cuboids (E = 1e7: the pressing world's first tries read over
    the limit, with patient re-solves and retries with less motion). The graph took every period
    after the first (the force limit's decisions on the device, ``limit_kernels``), with the host's
    solve count, and none ran in graphs in the reference."""
    steps = 60
    graphed_out, graphed, count = _run(True, substeps, steps, modulus=1e7)
    host_out, host, _ = _run(False, substeps, steps, modulus=1e7)
    assert count == substeps
    assert host.sum() == 0
    assert graphed[0] == 0  # the first period records the launches on the host
    assert (graphed[1:] == count).all(), graphed
    assert (graphed_out["extra_world_solves"] > 0).sum() >= 10, graphed_out["extra_world_solves"]
    assert graphed_out.keys() == host_out.keys()
    differ = [k for k in host_out if not np.array_equal(graphed_out[k], host_out[k], equal_nan=True)
              or graphed_out[k].dtype != host_out[k].dtype]
    assert not differ, differ[:10]


def _sideways_press(period_graphs: bool, monkeypatch=None):
    """The closed gripper pressed down and sideways onto a cylinder (E = 3e6) on the ground while its
    wrist turns back and forth (``test_wrist_force_limit``'s sustained push): stopped pads the
    object still pushes over the limit back off. Returns every observation and info array, on the
    host path (``monkeypatch`` given) the number of substeps a world backed off in, and the
    substeps the period graph ran."""
    from defgrasp_env.envs import scene as scene_module
    from defgrasp_env.layout import DELTA_ACTION, ENV_STATE

    backed = []
    if monkeypatch is not None:
        limited = scene_module.limited_substep

        def counting(*args, **kwargs):
            result = limited(*args, **kwargs)
            backed.append(int((result[2] < 0.0).sum()))
            return result
        monkeypatch.setattr(scene_module, "limited_substep", counting)
    env = gym.make("DeformablePickup-v0", object="cylinder", youngs_modulus=3e6)
    obs, _ = env.reset(seed=1)
    scene = env.unwrapped.scene
    scene.period_graphs = period_graphs
    out = {}
    for t in range(32):
        offset = ENV_STATE.get(obs["environment_state"], "feature_position") - scene.gripper.tcp_positions()[0]
        toward = np.clip(offset / 0.015, -1.0, 1.0)
        push = np.clip([toward[0] + 0.7, -1.0 if t > 5 else 0.0, toward[2]], -1.0, 1.0)
        action = DELTA_ACTION.pack(linear_velocity=push, angular_velocity=[0.0, 0.3 * (-1.0) ** t, 0.0], jaw=[1.0])
        obs, _, _, _, info = env.step(action.astype(np.float32))
        out.update({f"{t}/obs/{name}": np.asarray(v) for name, v in obs.items()})
        out.update({f"{t}/info/{name}": np.asarray(v) for name, v in info.items()})
    out["positions"] = scene.state.positions.numpy().copy()
    graphed = scene.device_substeps
    env.close()
    return out, sum(backed), graphed


def test_a_back_off_on_the_device_gives_the_hosts_bits(monkeypatch):
    """The force limit's back-off (``limit_kernels.back_off_begin``, ``Gripper.aim_back_off``) in
    the period graph against the host's ``limited_substep``: the cylinder pressed sideways while
    turning backs off in several substeps (4), and every observation, info and node position is equal
    bit for bit on the CPU."""
    host, backed, on_device = _sideways_press(False, monkeypatch)
    graphed, _, graphed_substeps = _sideways_press(True)
    assert on_device == 0 and graphed_substeps == 31 * 4, graphed_substeps  # every period but the first
    assert backed >= 3, backed
    differ = [k for k in host if not np.array_equal(graphed[k], host[k], equal_nan=True)]
    assert not differ, differ[:10]


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=pytest.mark.cuda)])
def test_the_gate_closes_exactly_where_the_host_would_raise(device):
    """``count_nonfinite`` + ``close_gate_if_nonfinite`` against the host (``SolveLoads.from_rows``
    raises on non-finite pad forces, whatever the load): loads under, at, over and far over the
    limit, inf and NaN keep the gate open where the host reads them (the limit's decisions are on
    the device), non-finite pad forces close it; the count stays until the period's next open."""
    from defgrasp_env.envs.limit_loads import SolveLoads

    if device != "cpu" and not wp.is_cuda_available():
        pytest.skip("no CUDA device")
    for load in (0.0, 1.0, 1.0 + FORCE_TOLERANCE, 1e6, np.inf, np.nan):
        for finite in (1.0, 0.0):
            for others in (0, 3):  # the world alone, or among worlds that pass
                rows = np.array([(0.2, 0.0, 0.5, 1.0, 0.0, 0.0)] * others + [(0.9, 1.0, load, finite, 0.0, 0.0)])
                try:
                    SolveLoads.from_rows(rows)
                    raises = False
                except FloatingPointError:
                    raises = True
                loads = wp.array(rows, dtype=solve_load_row, device=device)
                gate = wp.zeros(lk.GATE_SIZE, dtype=wp.int32, device=device)
                wp.launch(lk.open_period_gate, dim=1, inputs=[], outputs=[gate], device=device)
                wp.launch(lk.count_nonfinite, dim=len(rows), inputs=[loads], outputs=[gate], device=device)
                wp.launch(lk.mark_substep, dim=1, inputs=[2], outputs=[gate], device=device)
                wp.launch(lk.close_gate_if_nonfinite, dim=1, inputs=[], outputs=[gate], device=device)
                got = gate.numpy()
                assert got[lk.GATE_OPEN] == int(not raises) and got[lk.GATE_NONFINITE] == int(raises), (load, finite)
                assert got[lk.GATE_SUBSTEP] == 2


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=pytest.mark.cuda)])
def test_the_limits_retries_on_the_device_are_the_hosts(device):
    """``limit_begin`` / ``limit_trial`` / ``limit_update`` / ``retry_gate`` driven as the period
    graph drives them, against ``wrist.force_limit.limited_substep`` on the same synthetic solves:
    per world a load that grows with the motion fraction (0 up to a touch, then steeply: a pad
    pressing into an object; some already at the limit at the start, some held, some never over,
    some pressed over the limit already at fraction 0, which back off where they can, some of
    them still over at the far end of the back-off, where the stop stands),
    the same trials, solve by solve, and the same accepted scales and loads, bit for bit on the
    CPU (float64 on both sides; within 1e-12 on CUDA, whose compiler may fuse a multiply-add)."""
    if device != "cpu" and not wp.is_cuda_available():
        pytest.skip("no CUDA device")
    from defgrasp_env.wrist.force_limit import BACK_OFF, MAX_RETRIES, limited_substep

    rng = np.random.default_rng(11)
    w = 300
    touch = np.where(rng.random(w) < 0.3, rng.uniform(-1.6, 0.0, w), rng.uniform(0.0, 1.2, w))  # < 0: pressed
    slope = rng.uniform(0.3, 30.0, w)
    aimed = np.where(rng.random(w) < 0.2, 0.0, 1.0)[:, None] * rng.normal(0.0, 0.01, (w, 3))  # 0: cannot back off
    start = np.where(rng.random(w) < 0.15, 1.0, rng.uniform(0.0, 0.9, w))
    held = rng.random(w) < 0.1

    def load_of(fraction):
        return np.maximum(fraction - touch, 0.0) * slope

    host_trials = []

    def solve(fraction):
        host_trials.append(np.array(fraction))
        return None, load_of(fraction)

    _, host_load, host_scale = limited_substep(solve, start, held=held,
                                               can_back_off=lambda over: over & aimed.any(axis=1))
    assert 50 < (load_of(np.where(held, 0.0, 1.0)) > 1.0 + FORCE_TOLERANCE).sum() < w - 50  # both sides
    assert (host_scale < 0.0).sum() > 20 and (host_scale > 0.0).sum() > 20  # backed off, and moved
    stop_over = (load_of(np.zeros(w)) > 1.0 + FORCE_TOLERANCE) & (host_scale == 0.0)
    assert stop_over.sum() > 20  # the stop stands: no back-off possible, or none within the limit
    assert (stop_over & aimed.any(axis=1)).sum() > 5 and (stop_over & ~aimed.any(axis=1)).sum() > 5
    np.testing.assert_array_equal(host_load[stop_over], load_of(np.zeros(w))[stop_over])

    arr = functools.partial(wp.array, device=device)
    state = lk.LimitState()
    for name in ("scale", "lo", "hi", "f_lo", "f_hi", "side", "trial", "solved"):
        setattr(state, name, wp.zeros(w, dtype=wp.float64, device=device))
    state.searching = wp.zeros(w, dtype=wp.int32, device=device)
    gate = wp.zeros(lk.GATE_SIZE, dtype=wp.int32, device=device)
    limiting, retry, final, changed = (wp.zeros(1, dtype=wp.int32, device=device) for _ in range(4))
    fraction = arr(np.where(held, 0.0, 1.0), dtype=wp.float64)
    solve_worlds, patient_solved = wp.zeros(w, dtype=int, device=device), wp.zeros(w, dtype=wp.int32, device=device)

    def loads_of(fraction):
        rows = np.zeros((w, 6))
        rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3] = start, held, load_of(fraction), 1.0
        return arr(rows, dtype=solve_load_row)

    def launch(kernel, dim, inputs, outputs):
        wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=device)

    device_trials, loads = [np.where(held, 0.0, 1.0)], loads_of(np.where(held, 0.0, 1.0))
    launch(lk.limit_begin, w, [loads, fraction, FORCE_TOLERANCE, state], [gate])
    launch(lk.limit_gate, 1, [], [gate, limiting, retry, final])
    assert limiting.numpy()[0] == 1

    def limit_solve(use_scale):
        nonlocal loads
        launch(lk.limit_trial, w, [use_scale, state], [fraction, solve_worlds, patient_solved, gate])
        launch(lk.solve_gate, 1, [], [gate, changed])
        trial = fraction.numpy().copy()
        device_trials.append(trial)
        loads = loads_of(trial)  # the solve: only the changed worlds' loads could differ, and they are a function
        return trial

    def limited():  # period_graph's ``_limited``
        while retry.numpy()[0]:
            limit_solve(0)
            launch(lk.limit_update, w, [loads, FORCE_TOLERANCE, state], [gate])
            launch(lk.retry_gate, 1, [MAX_RETRIES], [gate, retry, final])
        if final.numpy()[0]:
            limit_solve(1)

    limited()
    launch(lk.back_off_begin, w, [loads, arr(aimed, dtype=wp.vec3d), FORCE_TOLERANCE, BACK_OFF, state], [gate])
    launch(lk.limit_gate, 1, [], [gate, limiting, retry, final])
    assert limiting.numpy()[0] == 1  # stopped worlds that still read over back off
    limited()
    assert len(device_trials) == len(host_trials) >= 4
    # CUDA may fuse the regula falsi's multiply-add (one rounding less): within 1e-12 there
    same = np.array_equal if device == "cpu" else functools.partial(np.allclose, rtol=1e-12, atol=1e-15)
    for host, dev in zip(host_trials, device_trials):
        assert same(host, dev)
    assert same(state.scale.numpy(), host_scale)
    assert same(load_of(device_trials[-1]), host_load)
    assert gate.numpy()[lk.GATE_SOLVES] == len(host_trials) - 1
    # the worlds each retry re-solves: those whose fraction changed since their last solve
    changed_worlds = sum(int(np.count_nonzero(b != a)) for a, b in zip(host_trials, host_trials[1:]))
    assert gate.numpy()[lk.GATE_WORLD_SOLVES] == changed_worlds > 0


@pytest.mark.cuda
def test_a_period_on_the_device_agrees_with_substeps_from_the_host_on_cuda():
    """On CUDA the float atomics' order differs run to run, so the two paths agree within rounding:
    5 steps of the approach (no contact yet; the pressing world touches at the 7th) move the
    nodes within 1e-5 m of each other, with the graph taking every period after the first."""
    if not wp.is_cuda_available():
        pytest.skip("no CUDA device")
    graphed_out, graphed, count = _run(True, 4, 5, "cuda:0")
    host_out, _, _ = _run(False, 4, 5, "cuda:0")
    assert graphed[1:].tolist() == [count] * 4
    np.testing.assert_allclose(graphed_out["state/positions"], host_out["state/positions"], atol=1e-5)
    np.testing.assert_allclose(graphed_out["4/reward"], host_out["4/reward"], atol=1e-4)
    np.testing.assert_allclose(graphed_out["4/gripper/q"], host_out["4/gripper/q"], atol=1e-6)


@pytest.mark.cuda
def test_the_force_limit_holds_inside_the_period_graph_on_cuda():
    """On CUDA (float atomics: no bitwise reference) the pressing stiff cuboid's periods run whole
    in the graph with the limit's retries and patient re-solves (world-solves beyond one per world
    and substep), and its bounds hold as on the host: wrist force within the limit + tolerance
    plus 40 N for what the limit does not bound (the object's impact; the same run on the CPU reads
    152 N against 165), everything finite."""
    if not wp.is_cuda_available():
        pytest.skip("no CUDA device")
    from defgrasp_env.wrist.force_limit import DEFAULT_WRIST_FORCE_LIMIT

    out, graphed, count = _run(True, 4, 40, "cuda:0", modulus=1e7)
    assert (graphed[1:] == count).all(), graphed
    assert (out["extra_world_solves"] > 0).sum() >= 5, out["extra_world_solves"]
    wrist = np.array([out[f"{k}/info/wrist_force"] for k in range(40)])
    assert np.isfinite(wrist).all() and wrist.max() <= DEFAULT_WRIST_FORCE_LIMIT * (1 + FORCE_TOLERANCE) + 40.0
    assert np.isfinite(out["state/positions"]).all()


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=pytest.mark.cuda)])
def test_an_unconverged_solves_load_counts_its_force_error(device):
    """``solve_loads`` against the host's ``actuator_load``: a converged solve's load is the pads'
    load; an unconverged one's (last update above the tolerance) adds its force error, the
    stiffest node's stiffness x that update over the smaller limit force, with the pads touching or
    not (the solution may touch where the iterate does not), reported on its own too; the deciding
    update is the one at which the reading plus that error reaches 1 (0 where the reading is not
    under 1); none with the limits off (no NaN from inf / inf), and a diverged update (inf) reads
    over any limit."""
    if device != "cpu" and not wp.is_cuda_available():
        pytest.skip("no CUDA device")
    from defgrasp_env.envs.scene_kernels import solve_loads
    from defgrasp_env.wrist.force_limit import actuator_load, tip_force_bound

    wrist_limit, grip_limit, tolerance, stiffness = 150.0, 20.0, 1e-5, 1.0e5
    unit = min(wrist_limit, tip_force_bound(grip_limit, wrist_limit))
    normal = np.array([[12.0, 9.0], [12.0, 9.0], [0.0, 0.0], [12.0, 9.0], [12.0, 0.0], [0.0, 0.0]], np.float32)
    pad_force = np.zeros((6, 2, 3), np.float32)
    pad_force[:, 0, 0], pad_force[:, 1, 0] = normal[:, 0], -normal[:, 1]
    pad_force[:5, :, 1] = 30.0  # a lift: the net force is 60 N up plus the squeeze's difference
    pad_force[2] = 0.0  # no pad touches the iterate
    pad_force[5, :, 1] = 0.4  # pads pressed down on the object: no normal force along the jaw
    last = np.array([5e-6, 2e-3, 2e-3, np.inf, 1e-4, 2e-3], np.float32)
    limits = np.tile([0.3, 0.0], (6, 1))

    def loads(wrist):
        out = wp.zeros(6, dtype=solve_load_row, device=device)
        wp.launch(solve_loads, dim=6, inputs=[wp.array(normal.ravel(), dtype=wp.float32, device=device),
                                              wp.array(pad_force.reshape(-1, 3), dtype=wp.vec3, device=device),
                                              wp.array(limits, dtype=wp.vec2d, device=device), wrist, grip_limit,
                                              wp.array(last, dtype=wp.float32, device=device), tolerance,
                                              wp.full(6, stiffness, dtype=wp.float32, device=device),
                                              min(wrist, tip_force_bound(grip_limit, wrist))],
                  outputs=[out], device=device)
        return out.numpy()

    got = loads(wrist_limit)
    pads = actuator_load(np.linalg.norm(pad_force.sum(axis=1), axis=1), normal, wrist_limit, grip_limit)
    margin = np.float32(stiffness) * last / unit
    expected = pads + np.array([0.0, margin[1], margin[2], np.inf, margin[4], margin[5]])
    np.testing.assert_allclose(got[:, 2], expected, rtol=1e-6)
    np.testing.assert_allclose(got[:, 4], expected - pads, rtol=1e-6)
    assert (pads < 1.0).all()
    deciding = (1.0 - pads) * unit / np.float32(stiffness)
    np.testing.assert_allclose(got[:, 5], deciding, rtol=1e-6)
    # at the deciding update the reading plus its error is 1
    np.testing.assert_allclose(pads + np.float32(stiffness) * deciding / unit, 1.0, rtol=1e-9)
    assert got[1, 2] > 1.0 + FORCE_TOLERANCE > got[0, 2]  # 200 N of margin: the unconverged solve is re-solved
    assert np.array_equal(got[:, 0:2], limits) and (got[:, 3] == 1.0).all()
    off = loads(np.inf)
    assert not np.isnan(off[:, 2]).any() and (off[:, 2] == 0.0).all()
    assert (off[:, 4:] == 0.0).all()
    # a 40 N wrist limit: the lifts (60 N) read over it, and nothing decides them short of the limit
    low = loads(40.0)
    over = actuator_load(np.linalg.norm(pad_force.sum(axis=1), axis=1), normal, 40.0, grip_limit) >= 1.0
    assert over[[0, 1, 3, 4]].all() and not over[[2, 5]].any()
    assert (low[over, 5] == 0.0).all() and (low[~over, 5] > 0.0).all()


def test_a_load_is_certainly_over_only_past_its_whole_error():
    """``SolveLoads.certainly_over``: the load as read (load - error) still over 1 + tolerance
    after taking the error off once more; a converged solve (error 0) is certainly over as soon as
    it is over; a diverged one (error inf) never is (its patient re-solve is refused by the solver's
    divergence flag, not skipped here), and no NaN warning comes of inf - inf."""
    from defgrasp_env.envs.limit_loads import SolveLoads

    bound = 1.0 + FORCE_TOLERANCE
    load = np.array([bound + 0.01, bound + 0.01, 3.0, 3.0, np.inf, 0.5])
    error = np.array([0.0, 0.01, 0.9, 1.0, np.inf, 0.2])
    loads = SolveLoads(start=np.zeros(6), held=np.zeros(6, bool), load=load, error=error, deciding=np.zeros(6))
    with np.errstate(all="raise"):
        got = loads.certainly_over()
    # 3.0 - 2 x 0.9 = 1.2 > 1.1; 3.0 - 2 x 1.0 = 1.0 is not
    assert got.tolist() == [True, False, True, False, False, False]


def test_the_patient_re_solve_is_asked_only_where_it_can_change_the_decision_or_the_kept_forces():
    """``SolveLoads.patient_re_solve`` world by world: under the limit, none; over only with its
    error and moved, a re-solve to half its deciding update; certainly over and moved, none (the
    limit retries with less motion); certainly over and not moved (stopped or held: its forces
    are kept), a re-solve to the Newton tolerance (target 0); a world the caller does not allow
    (converged, or patient already), none."""
    from defgrasp_env.envs.limit_loads import PATIENT_UPDATE_FRACTION, SolveLoads

    load = np.array([0.5, 1.5, 3.0, 3.0, 1.5, 1.5])
    error = np.array([0.1, 0.8, 0.5, 0.5, 0.8, 0.0])
    deciding = np.array([4e-4, 2e-5, 0.0, 0.0, 2e-5, 0.0])
    fraction = np.array([1.0, 1.0, 1.0, 0.0, 0.3, 1.0])
    allowed = np.array([True, True, True, True, False, True])
    loads = SolveLoads(start=np.zeros(6), held=np.zeros(6, bool), load=load, error=error, deciding=deciding)
    patient, target = loads.patient_re_solve(fraction, allowed)
    assert patient.tolist() == [False, True, False, True, False, False]  # the last: converged, over: no re-solve can help
    assert target[1] == PATIENT_UPDATE_FRACTION * 2e-5 and target[3] == 0.0


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=pytest.mark.cuda)])
def test_the_graphs_patient_re_solve_is_the_hosts(device):
    """``choose_patient`` against the host's rule (``SolveLoads.patient_re_solve`` of a solve's
    fraction among the worlds whose solve did not converge or diverged and whose last solve was
    not patient; ``advance``'s stored target, at least the Newton tolerance, in float32) world by
    world over random loads: under and over the limit, with and without their error, moved or not
    (fraction 0, 1 or a retry's), converged or not, patient already or not, a diverged update (inf
    error); a first try clears the patient marks; non-finite worlds are never patient;
    ``patient_gate`` opens only where a world is patient and no solve was non-finite, and counts
    the re-solve."""
    if device != "cpu" and not wp.is_cuda_available():
        pytest.skip("no CUDA device")
    from defgrasp_env.envs.limit_loads import PATIENT_UPDATE_FRACTION, SolveLoads

    rng = np.random.default_rng(5)
    w, tol = 400, 1e-5
    rows = np.zeros((w, 6))
    rows[:, 0] = rng.uniform(0.0, 1.2, w)
    rows[:, 1] = rng.random(w) < 0.3  # held
    rows[:, 4] = np.where(rng.random(w) < 0.4, 0.0, rng.uniform(0.0, 2.0, w))
    rows[:, 2] = rng.uniform(0.0, 4.0, w) + rows[:, 4]
    rows[:, 3] = 1.0
    rows[:, 5] = np.where(rows[:, 2] < 1.0, rng.uniform(0.0, 1e-3, w), 0.0)
    rows[:3, 4], rows[:3, 2] = np.inf, np.inf  # diverged
    fraction = np.where(rng.random(w) < 0.3, 0.0, np.where(rng.random(w) < 0.5, 1.0, rng.uniform(0.0, 1.0, w)))
    unconverged = (rng.random(w) < 0.6).astype(np.int32)
    diverged = np.zeros(w, np.int32)
    diverged[:3] = 1
    solved = (rng.random(w) < 0.2).astype(np.int32)  # the last solve was patient already
    loads = SolveLoads.from_rows(rows)
    allowed = (unconverged != 0) | (diverged != 0)

    def launch(rows, first):
        arr = functools.partial(wp.array, device=device)
        marks = arr(solved, dtype=wp.int32)
        out = [wp.zeros(w, dtype=int, device=device), wp.zeros(w, dtype=float, device=device),
               wp.zeros(lk.GATE_SIZE, dtype=wp.int32, device=device)]
        wp.launch(lk.choose_patient, dim=w,
                  inputs=[arr(rows, dtype=solve_load_row), arr(fraction, dtype=wp.float64), marks, int(first),
                          arr(unconverged, dtype=int), arr(diverged, dtype=int), FORCE_TOLERANCE,
                          PATIENT_UPDATE_FRACTION, tol], outputs=out, device=device)
        gate = out[2].numpy().copy()
        cond = wp.zeros(1, dtype=wp.int32, device=device)
        wp.launch(lk.patient_gate, dim=1, inputs=[], outputs=[out[2], cond], device=device)
        return out[0].numpy(), out[1].numpy(), gate, out[2].numpy(), int(cond.numpy()[0])

    for first in (True, False):
        patient, target = loads.patient_re_solve(fraction, allowed & (first | (solved == 0)))
        assert 20 < patient.sum() < w - 20 and (patient & (fraction == 0)).any() and (patient & (fraction > 0)).any()
        got_patient, got_update, counted, gate, cond = launch(rows, first)
        assert np.array_equal(got_patient != 0, patient)
        assert np.array_equal(got_update, np.maximum(target, tol).astype(np.float32))
        assert counted[lk.GATE_PATIENT] == patient.sum() and cond == 1
        assert gate[lk.GATE_SOLVES] == 1 and gate[lk.GATE_WORLD_SOLVES] == patient.sum()
        assert gate[lk.GATE_PATIENT] == 0  # cleared for the next choice
    bad = rows.copy()
    bad[[5, 9], 3] = 0.0  # non-finite pad forces: never patient (the host raises on them)
    got_patient, _, counted, _, _ = launch(bad, True)
    first_patient, _ = loads.patient_re_solve(fraction, allowed)
    assert got_patient[[5, 9]].tolist() == [0, 0]
    assert counted[lk.GATE_PATIENT] == first_patient.sum() - first_patient[[5, 9]].sum()
    stopped = wp.zeros(lk.GATE_SIZE, dtype=wp.int32, device=device)
    stopped.assign(np.array([1, 0, 0, 0, 3, 1] + [0] * (lk.GATE_SIZE - 6), np.int32))  # 3 patient, a non-finite solve
    cond = wp.ones(1, dtype=wp.int32, device=device)
    wp.launch(lk.patient_gate, dim=1, inputs=[], outputs=[stopped, cond], device=device)
    assert cond.numpy()[0] == 0 and stopped.numpy()[lk.GATE_SOLVES] == 0 and stopped.numpy()[lk.GATE_NONFINITE] == 1
    calm = rows.copy()
    calm[:, 2] = 0.5  # none over: no re-solve
    got_patient, _, _, gate, cond = launch(calm, True)
    assert not got_patient.any() and cond == 0 and gate[lk.GATE_WORLD_SOLVES] == 0
