"""Branch switching at a located branch point, from the reduced (Lyapunov-Schmidt) equations.

At (u*, p*) with kernel V (n, d) (d = 1 or 2), u = u* + dp s + V xi + w (s = du/dp of the parent,
w in range(J)); the reduced energy is g(xi, dp) = dp/2 xi^T B xi + T(xi) + ..., with
    B = V^T (dJ/dp along the parent) V          (jvp of the Hessian-vector product),
    T = T3(xi) = E'''[h, h, h]/6,  h = V xi     (if not negligible: transcritical-like), else
    T = T4(xi) = E''''[h]^4/24 - b^T J^+ b/8,   b = P E'''[h, h, .]  (the range correction),
T homogeneous of degree m = k + 1 (k = 2 or 3). A branch xi = r eta (|eta| = 1) needs
det[B eta, grad T(eta)] = 0, then kappa = m T(eta) / eta^T B eta and dp = -kappa r^(k-1). For
d = 2, T is fitted from 5 samples and the directions are the roots in the angle of eta (Brent);
if every direction solves it (an O(2) circle) the kernel basis is returned, ``isolated=False``.
The Morse index of each branch is predicted from r^(k-1) (Hess T(eta) - kappa B) plus the
negative eigenvalues outside the kernel.
"""
from __future__ import annotations

from dataclasses import dataclass
from math import factorial

import jax.numpy as jnp
import numpy as np
from scipy.optimize import brentq

from .continuation import continuation
from .scales import scaled_options


@dataclass
class Emanating:
    """A branch out of a branch point: u ~ u* + r vector + r^2 curvature + dp parent_slope,
    p = p* + dp, dp = -kappa r^(order-1), for r > 0 and r < 0. eta (d,) unit kernel coordinates;
    vector = V eta, curvature = -J^+ P E'''[vector, vector, .]/2 (n,) (keeps Newton on this branch);
    predicted_morse = (for r > 0, for r < 0), without the circle's zero mode when not isolated."""

    eta: np.ndarray
    vector: np.ndarray
    kappa: float
    order: int
    parent_slope: np.ndarray
    predicted_morse: tuple
    curvature: np.ndarray
    isolated: bool = True


def _dpoly(c, xi, di, dj):
    """d^(di+dj)/dxi1^di dxi2^dj of sum_i c_i xi1^(m-i) xi2^i."""
    m, total = len(c) - 1, 0.0
    for i, ci in enumerate(c):
        e1, e2 = m - i, i
        if e1 >= di and e2 >= dj:
            falling = factorial(e1) / factorial(e1 - di) * factorial(e2) / factorial(e2 - dj)
            total += ci * falling * xi[0] ** (e1 - di) * xi[1] ** (e2 - dj)
    return total


def emanating_directions(problem, event, *, cubic_tol=1e-8, circle_tol=1e-8):
    """Emanating branches (list of Emanating) at a branch-point Event, from its reduced equations.

    cubic_tol: the cubic term is dropped (a pitchfork) below cubic_tol of its natural size;
    circle_tol: d = 2, every direction solves (a circle family) when det[B eta, grad T(eta)] stays
    below circle_tol of its scale |B| |T| m (not roundoff: a stiff problem's quartic can be a
    small difference of large terms).
    """
    V = np.asarray(event.v)
    n, d = V.shape
    if d > 2:
        raise NotImplementedError(f"branch switching with a {d}-dimensional kernel")
    reduced = _ReducedEquations(problem, event, V)
    m0 = min(event.morse_before, event.morse_after)
    if d == 1:
        samples = np.array([[1.0]])
    else:
        th = np.arange(5) * np.pi / 5
        samples = np.stack([np.cos(th), np.sin(th)], axis=1)
    sampled = [reduced.terms(xi) for xi in samples]
    T = np.array([t[:2] for t in sampled])  # (samples, 2)
    # the cubic term counts unless below cubic_tol of the quartic one and of its natural size
    scale3 = max(float(np.max(np.abs(T))), max(t[3] for t in sampled))
    k = 2 if np.max(np.abs(T[:, 0])) > cubic_tol * scale3 else 3
    m = k + 1
    B, slope = reduced.B, reduced.slope
    if d == 1:
        c = T[0, k - 2]
        kappa = m * c / B[0, 0]
        h = m * (m - 2) * c  # reduced Hessian / r^(k-1)
        morse = (m0 + int(h < 0), m0 + int(h * (-1) ** (k - 1) < 0))
        return [Emanating(np.array([1.0]), V[:, 0], kappa, k, slope, morse, -0.5 * reduced.terms(np.array([1.0]))[2])]
    M = np.stack([samples[:, 0] ** (m - i) * samples[:, 1] ** i for i in range(m + 1)], axis=1)
    c = np.linalg.lstsq(M, T[:, k - 2], rcond=None)[0]
    roots, isolated = _planar_directions(c, B, m, circle_tol)
    out = []
    for theta in roots:
        eta = np.array([np.cos(theta), np.sin(theta)])
        kappa = m * _dpoly(c, eta, 0, 0) / float(eta @ B @ eta)
        H = np.array([[_dpoly(c, eta, 2, 0), _dpoly(c, eta, 1, 1)], [_dpoly(c, eta, 1, 1), _dpoly(c, eta, 0, 2)]])
        ev = np.linalg.eigvalsh(H - kappa * B)
        if not isolated:  # the circle's own direction is a zero mode (its sign is noise): not counted
            ev = ev[np.argsort(np.abs(ev))[1:]]
        morse = (m0 + int(np.sum(ev < 0)), m0 + int(np.sum(ev * (-1) ** (k - 1) < 0)))
        out.append(Emanating(eta, V @ eta, kappa, k, slope, morse, -0.5 * reduced.terms(eta)[2], isolated))
    return out


class _ReducedEquations:
    """The pieces of the reduced equations at a branch-point Event with kernel V (n, d): the
    parent slope du/dp, B = V^T (dJ/dp along the parent) V, and the cubic and quartic terms
    ``terms(xi)`` at kernel coordinates xi."""

    def __init__(self, problem, event, V):
        self.problem, self.V, self.args = problem, V, problem.args
        args, d = self.args, V.shape[1]
        self.u, self.p = jnp.asarray(event.u), jnp.asarray(event.p)
        F, self.J, Fp = problem.linearise(self.u, self.p, args)
        self.Zd = np.zeros((d, d))
        # parent slope du/dp: -J^+ F_p on range(J) plus the kernel part of the parent tangent
        y, _ = problem.backend.bordered_solve(self.J, V, V, self.Zd, -Fp, np.zeros(d))
        t = np.asarray(event.tangent)
        self.slope = np.asarray(y) + V @ (V.T @ t[:-1]) / t[-1]
        dJ = [problem.hvp_derivative(self.u, self.p, args, jnp.asarray(V[:, i]), jnp.asarray(self.slope),
                                     jnp.ones_like(self.p))
              for i in range(d)]
        B = V.T @ np.stack([np.asarray(g) for g in dJ], axis=1)
        self.B = 0.5 * (B + B.T)

    def terms(self, xi):
        """(T3, T4, J^+ P E'''[h, h, .], |h| |E'''[h, h, .]| / 6) at kernel coordinates xi."""
        problem, V = self.problem, self.V
        h = jnp.asarray(V @ xi)
        f2, f3 = (np.asarray(a) for a in problem.directional_derivatives(self.u, self.p, self.args, h))
        b = f2 - V @ (V.T @ f2)
        x, _ = problem.backend.bordered_solve(self.J, V, V, self.Zd, b, np.zeros(V.shape[1]))
        T3, T4 = float(h @ f2) / 6, float(h @ f3) / 24 - float(b @ np.asarray(x)) / 8
        return T3, T4, np.asarray(x), float(np.linalg.norm(h) * np.linalg.norm(f2)) / 6


def _planar_directions(c, B, m, circle_tol):
    """The angles theta of the emanating directions eta = (cos, sin) of a 2-dimensional kernel:
    the roots of det[B eta, grad T(eta)] (T the degree-m form of coefficients c), bracketed on a
    grid of [0, pi) and refined by Brent. -> (roots, isolated); where it vanishes everywhere (an
    O(2) circle of solutions) the kernel basis (0, pi/2), isolated False."""
    def hfun(theta):  # det[B eta, grad T(eta)]: zero on emanating directions
        eta = np.array([np.cos(theta), np.sin(theta)])
        g, be_ = np.array([_dpoly(c, eta, 1, 0), _dpoly(c, eta, 0, 1)]), B @ eta
        return be_[0] * g[1] - be_[1] * g[0]

    grid = (np.arange(360) + 0.5) * np.pi / 360
    hv = np.array([hfun(x) for x in grid])
    scale = np.max(np.abs(B)) * np.max(np.abs(c)) * m
    if np.max(np.abs(hv)) <= circle_tol * scale:  # every direction: a continuous (O(2)) family
        return [0.0, 0.5 * np.pi], False
    ends = np.append(grid, grid[0] + np.pi)
    vals = np.append(hv, (-1) ** m * hv[0])
    return [brentq(hfun, ends[i], ends[i + 1], xtol=1e-15) for i in range(360) if vals[i] * vals[i + 1] < 0], True


def switch_branches(problem, event, alg, opts, *, amplitude=None, directions=None, throw=True):
    """Continue every emanating branch of a branch-point Event, both signs of r. -> [Branch].

    Each starts from the reduced-equation predictor at |r| = amplitude (default |opts.ds|), moving
    away from the branch point; ``branch.origin`` holds the Emanating direction and the sign.
    """
    opts = scaled_options(problem, opts, event.u, event.p)
    dirs = emanating_directions(problem, event) if directions is None else directions
    r0 = abs(opts.ds) if amplitude is None else float(amplitude)
    branches = []
    for e in dirs:
        for sign in (1, -1):
            r = sign * r0
            dp = -e.kappa * r ** (e.order - 1)
            ddp = -(e.order - 1) * e.kappa * r ** (e.order - 2)  # d(dp)/dr
            u = np.asarray(event.u) + r * e.vector + r * r * e.curvature + dp * e.parent_slope
            t = sign * np.append(e.vector + 2 * r * e.curvature + ddp * e.parent_slope, ddp)
            br = continuation(problem, alg, opts, start=(u, event.p + dp, t), throw=throw)
            br.origin = {"event": event, "direction": e, "sign": sign}
            branches.append(br)
    return branches
