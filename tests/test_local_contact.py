"""The local contact problem (one contact, the others held fixed) against its exact answers.

For mobility W (symmetric positive definite), velocity u without this contact's impulse,
normal n, target normal velocity c and friction mu, the impulse P must satisfy the
Signorini-Coulomb conditions: P_n >= 0, (u + W P) . n >= c with equality when P_n > 0,
|P_t| <= mu P_n, and a sticking contact has no tangential velocity, a sliding one a tangential
velocity opposite to P_t (maximal dissipation) with |P_t| = mu P_n.
"""

import numpy as np
import pytest
import warp as wp

from rodwarp import _warp
from rodwarp.kernels.friction import local_frame, solve_contact
from rodwarp.kernels.structs import StepParams

_warp.init()


@wp.kernel
def _solve(W: wp.array(dtype=wp.mat33d), u: wp.array(dtype=wp.vec3d), n: wp.array(dtype=wp.vec3d),
           target: wp.array(dtype=wp.float64), mu: wp.float64, P0: wp.array(dtype=wp.vec3d),
           guess: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.vec3d)):
    k = wp.tid()
    f = local_frame(W[k], n[k], target[k])
    f.gamma = guess[k]  # the sliding multiplier a sweep before left (a warm start only)
    params = StepParams()
    params.law = 0  # the exact law: Signorini and the Coulomb cone
    # solve_contact takes the velocity with the current impulse applied: u + W P0
    P, gamma = solve_contact(u[k] + W[k] * P0[k], f, n[k], P0[k], mu, params)
    out[k] = P


def _cases(rng, m, coupled: bool):
    n = rng.normal(size=(m, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    W = np.empty((m, 3, 3))
    for k in range(m):
        if coupled:  # a rigid rod's mobility: I / m - [r]x I^-1 [r]x, plus the other side's
            A = rng.normal(size=(3, 3))
            W[k] = 0.5 * np.eye(3) + A @ A.T
        else:  # normal and tangent decoupled: W = a n n^T + B_t
            e1 = np.cross(n[k], [1.0, 0.0, 0.0] if abs(n[k, 0]) < 0.9 else [0.0, 1.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(n[k], e1)
            T = np.stack([e1, e2], axis=1)
            B = rng.normal(size=(2, 2))
            W[k] = (0.5 + rng.random()) * np.outer(n[k], n[k]) + T @ (0.3 * np.eye(2) + B @ B.T) @ T.T
    # approaching (mostly) or separating along n, with tangential slip of all sizes
    u = rng.normal(size=(m, 3)) * rng.choice([0.05, 0.3, 1.0], size=(m, 1)) + n * rng.uniform(-2.0, 0.5, size=(m, 1))
    target = np.where(rng.random(m) < 0.5, 0.0, -np.abs(rng.normal(size=m)))
    P0 = rng.normal(size=(m, 3)) * 0.1  # any previous impulse: the answer must not depend on it
    return W, u, n, target, P0


def _run(W, u, n, target, mu, P0, guess=None):
    out = wp.zeros(len(u), dtype=wp.vec3d, device="cpu")
    guess = np.zeros(len(u)) if guess is None else guess
    wp.launch(_solve, dim=len(u), device="cpu",
              inputs=[wp.array(W, dtype=wp.mat33d, device="cpu"), wp.array(u, dtype=wp.vec3d, device="cpu"),
                      wp.array(n, dtype=wp.vec3d, device="cpu"), wp.array(target, dtype=wp.float64, device="cpu"),
                      float(mu), wp.array(P0, dtype=wp.vec3d, device="cpu"), wp.array(guess, dtype=wp.float64,
                                                                                       device="cpu"), out])
    return out.numpy()


def _split(P, w, n):
    pn = np.einsum("ij,ij->i", P, n)
    wn = np.einsum("ij,ij->i", w, n)
    return pn, P - pn[:, None] * n, wn, w - wn[:, None] * n


@pytest.mark.parametrize("coupled", [False, True])
def test_sticking_and_separating_contacts_take_their_exact_impulse(coupled):
    rng = np.random.default_rng(1 if coupled else 2)
    W, u, n, target, P0 = _cases(rng, 400, coupled)
    mu = 0.5
    P = _run(W, u, n, target, mu, P0)
    stick = np.linalg.solve(W, (target[:, None] * n - u)[..., None])[..., 0]
    sn, st, _, _ = _split(stick, stick, n)
    sticks = (sn > 0) & (np.linalg.norm(st, axis=1) <= mu * sn)
    free = np.einsum("ij,ij->i", u, n) >= target
    assert sticks.sum() > 40 and free.sum() > 40  # both cases are exercised
    # separating (no approach without an impulse): none
    assert np.abs(P[free]).max() == 0.0
    # sticking: exactly W^-1 (c n - u), so the contact velocity is c n
    np.testing.assert_allclose(P[sticks & ~free], stick[sticks & ~free], rtol=1e-10, atol=1e-12)
    w = u + np.einsum("kij,kj->ki", W, P)
    np.testing.assert_allclose(w[sticks & ~free], target[sticks & ~free, None] * n[sticks & ~free], atol=1e-10)


@pytest.mark.parametrize("guess", ["none", "far above", "random"])
def test_sliding_contacts_lie_on_the_cone_with_maximal_dissipation(guess):
    """With the normal and tangent parts decoupled the local solve is exact for sliding too,
    whatever sliding multiplier the last sweep left as the Newton iteration's start (its
    root is bracketed from below, so a guess above it costs an iteration, not accuracy)."""
    rng = np.random.default_rng(3)
    W, u, n, target, P0 = _cases(rng, 400, False)
    mu = 0.3
    g = {"none": None, "far above": np.full(len(u), 1e3), "random": rng.uniform(0.0, 5.0, len(u))}[guess]
    P = _run(W, u, n, target, mu, P0, g)
    w = u + np.einsum("kij,kj->ki", W, P)
    pn, pt, wn, wt = _split(P, w, n)
    assert np.all(pn >= 0)
    assert np.all(wn >= target - 1e-10)  # never approaching faster than the target
    np.testing.assert_allclose(wn[pn > 0], target[pn > 0], atol=1e-10)  # complementarity
    lt = np.linalg.norm(pt, axis=1)
    assert np.all(lt <= mu * pn * (1 + 1e-9) + 1e-15)
    slide = (pn > 0) & (np.linalg.norm(wt, axis=1) > 1e-8)
    assert slide.sum() > 40
    np.testing.assert_allclose(lt[slide], mu * pn[slide], rtol=1e-9)  # on the cone's edge
    # the tangential velocity opposes the tangential impulse
    cos = np.einsum("ij,ij->i", pt[slide], wt[slide]) / (lt[slide] * np.linalg.norm(wt[slide], axis=1))
    np.testing.assert_allclose(cos, -1.0, atol=1e-8)
