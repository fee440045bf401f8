"""FEM core: the polar rotation of the elastic kernels (warm-started Newton iteration on SO(3) with
an SVD fallback) against the polar decomposition computed in float64 numpy from the SVD.

Truth: R = U diag(1, 1, det(U V^T)) V^T for F = U S V^T, the rotation that maximises tr(R^T F)
over SO(3) (for det F < 0 this is the fixed-corotated model's R with a negative smallest singular
value). Tolerance 2e-6 per entry: the kernel works in float32 (u = 6e-8) and stops once its update
is below 1e-7 rad; the error of R is about u times the condition of the polar problem,
max (s_i + s_j) / min (s_i + s_j), which is below 25 for the matrices here (measured: <= 7.3e-7).
Warp's float32 ``svd3`` alone is off by up to 6e-4 on the same matrices, so these bounds also
check that the SVD fallback is refined.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from defgrasp_env.sim.kernels.elastic import frame_rotation, polar_rotation
from defgrasp_env.transforms import matrix_to_quat, quat_to_matrix

ROTATION_TOL = 2e-6


@wp.kernel
def polar_kernel(f: wp.array(dtype=wp.mat33), guess: wp.array(dtype=wp.quat), out: wp.array(dtype=wp.mat33)):
    i = wp.tid()
    out[i] = wp.quat_to_matrix(polar_rotation(f[i], guess[i]))


def reference_rotation(f: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(f)
    return u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt


def random_rotations(rng, count) -> np.ndarray:
    q = rng.normal(size=(count, 4))
    return quat_to_matrix(q / np.linalg.norm(q, axis=1, keepdims=True))


def turned(r: np.ndarray, angle: float, rng) -> np.ndarray:
    """r turned by ``angle`` rad about random axes."""
    axis = rng.normal(size=(len(r), 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    k = np.zeros((len(r), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    k -= k.transpose(0, 2, 1)
    turn = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    return turn @ r


def run(f: np.ndarray, guess_rotations: np.ndarray, device: str = "cpu") -> np.ndarray:
    fa = wp.array(f.astype(np.float32), dtype=wp.mat33, device=device)
    ga = wp.array(matrix_to_quat(guess_rotations).astype(np.float32), dtype=wp.quat, device=device)
    out = wp.zeros(len(f), dtype=wp.mat33, device=device)
    wp.launch(polar_kernel, len(f), inputs=[fa, ga, out], device=device)
    return out.numpy().astype(np.float64)


def deformations(rng, count: int, inverted: bool) -> np.ndarray:
    """F = R0 S with S symmetric, singular values in [0.6, 1.5] (one of them negative if inverted)."""
    r0 = random_rotations(rng, count)
    q = random_rotations(rng, count)
    s = rng.uniform(0.6, 1.5, size=(count, 3))
    if inverted:
        s[:, 2] = -rng.uniform(0.1, 0.5, size=count)  # the smallest one flips (inverted tet)
    return r0 @ q @ (s[:, :, None] * q.transpose(0, 2, 1))


@pytest.mark.parametrize("inverted", [False, True], ids=["det>0", "det<0"])
@pytest.mark.parametrize("guess_error_rad", [0.0, 1e-3, 0.3, 2.0, np.pi])
def test_polar_rotation_matches_svd_from_any_guess(inverted, guess_error_rad, device="cpu"):
    """Warm starts near the answer (Newton converges), far from it (0.3-2 rad) and at the
    antipodal stationary points (pi): the result is always the maximising rotation."""
    rng = np.random.default_rng(int(guess_error_rad * 100) + inverted)
    f = deformations(rng, 200, inverted)
    truth = np.stack([reference_rotation(m) for m in f])
    got = run(f, turned(truth, guess_error_rad, rng), device)
    assert np.abs(got - truth).max() < ROTATION_TOL
    assert np.allclose(np.linalg.det(got), 1.0, atol=1e-5)


def test_polar_rotation_of_a_rotation_is_itself_even_from_the_opposite_guess():
    """F = a rotation, guess turned by exactly pi about an axis: tr(R^T F) is stationary there
    (a minimum along that axis), so a method that only checks for a zero gradient would return
    the guess; the kernel must recognise it is not the maximum."""
    rng = np.random.default_rng(3)
    r = random_rotations(rng, 50)
    got = run(r, turned(r, np.pi, rng))
    assert np.abs(got - r).max() < ROTATION_TOL


@wp.kernel
def seed_kernel(f: wp.array(dtype=wp.mat33), frame: wp.array(dtype=wp.mat33), seed: wp.array(dtype=wp.mat33)):
    """``elastic.seed_rotation_tet``'s rotation of F (and the frame it starts from)."""
    i = wp.tid()
    q = frame_rotation(f[i])
    frame[i] = wp.quat_to_matrix(q)
    seed[i] = wp.quat_to_matrix(polar_rotation(f[i], q))


@pytest.mark.parametrize("inverted", [False, True], ids=["det>0", "det<0"])
def test_a_substeps_seed_is_the_polar_rotation(inverted):
    """A substep's seed (Newton from F's Gram-Schmidt frame, the SVD where that fails) is the
    maximising rotation within the same bound, for any orientation and stretches of 0.6-1.5 (and
    inverted tets); the frame itself is a rotation, within 0.5 rad of the answer where det F > 0
    (Newton's start); degenerate F (a zero column, two parallel columns, F = 0) get the identity frame and
    still a rotation (their polar rotation is not unique)."""
    rng = np.random.default_rng(11 + inverted)
    f = deformations(rng, 300, inverted)
    degenerate = np.array([[[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                           [[1.0, 2.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]],
                           np.zeros((3, 3))])
    f = np.concatenate([f, degenerate])
    fa = wp.array(f.astype(np.float32), dtype=wp.mat33, device="cpu")
    frame, seed = (wp.zeros(len(f), dtype=wp.mat33, device="cpu") for _ in range(2))
    wp.launch(seed_kernel, len(f), inputs=[fa, frame, seed], device="cpu")
    frame, seed = frame.numpy().astype(np.float64), seed.numpy().astype(np.float64)
    truth = np.stack([reference_rotation(m) for m in f[:-3]])  # F with two zero singular values: not unique
    assert np.abs(seed[:-3] - truth).max() < ROTATION_TOL
    assert np.allclose(seed @ seed.transpose(0, 2, 1), np.eye(3), atol=1e-5)
    assert np.allclose(frame @ frame.transpose(0, 2, 1), np.eye(3), atol=1e-5)
    assert np.allclose(np.linalg.det(frame), 1.0, atol=1e-5)
    assert np.allclose(frame[-3:], np.eye(3), atol=1e-6)
    angle = np.arccos(np.clip((np.einsum("nij,nij->n", frame[:-3], truth) - 1.0) / 2.0, -1.0, 1.0))
    if not inverted:  # an inverted tet's polar rotation is far from its frame: Newton fails there, the SVD seeds it
        assert angle.max() < 0.5, angle.max()  # measured 0.44 rad


@pytest.mark.cuda
@pytest.mark.parametrize("inverted", [False, True], ids=["det>0", "det<0"])
def test_polar_rotation_on_cuda(inverted):
    """The same kernel compiled for the GPU (same bounds)."""
    test_polar_rotation_matches_svd_from_any_guess(inverted, 2.0, device="cuda:0")
