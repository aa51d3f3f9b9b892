"""Predictor-corrector core, generic in the system G(x, lam) = 0, x (m,), lam scalar.

``lin(x, lam) -> (G (m,), A = dG/dx (m, m), a = dG/dlam (m,))``. For the equilibrium problem x = u,
lam = p, A = J; for a fold curve x = (u, p), lam = mu. z = (x, lam) (m+1,) and the tangent t (m+1,)
is a unit vector. Arrays are NumPy between steps (the control flow is Python), JAX inside lin.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Correction:
    z: np.ndarray
    iterations: int
    converged: bool
    residual: float
    lin: tuple  # (G, A, a) at z (the last evaluation), reused for the tangent and the spectrum


def tangent(backend, A, a, t_prev):
    """Unit kernel vector of [A, a] (m, m+1), oriented so that <t, t_prev> > 0, from
    [[A, a], [t_prev^T]] y = [0; 1] (regular at folds, singular only at branch points)."""
    t_prev = np.asarray(t_prev)
    m = t_prev.size - 1
    y, y_lam = backend.bordered_solve(A, a, t_prev[:-1], t_prev[-1], np.zeros(m), 1.0)
    y = np.append(np.asarray(y), float(y_lam))
    return y / np.linalg.norm(y)  # <y, t_prev> = 1 > 0: orientation kept by construction


def correct(backend, lin, z_pred, t, tol, max_iter):
    """Newton on [G(z); <z - z_pred, t>] = 0 from z_pred (Keller's arclength constraint): converged
    when the residual norm is <= tol, not after max_iter solves or on a non-finite residual."""
    z = np.asarray(z_pred, dtype=float)
    res, it = np.inf, 0
    for it in range(max_iter + 1):
        G, A, a = lin(z[:-1], z[-1])
        with np.errstate(over="ignore", invalid="ignore"):  # a diverging iterate: inf, a failed step
            r = float(np.dot(z - z_pred, t))
            res = float(np.sqrt(np.sum(np.asarray(G) ** 2) + r * r))
        if not np.isfinite(res) or res <= tol or it == max_iter:
            break
        dx, dlam = backend.bordered_solve(A, a, t[:-1], t[-1], -np.asarray(G), -r)
        z = z + np.append(np.asarray(dx), float(dlam))
    return Correction(z, it, bool(res <= tol), res, (G, A, a))


@dataclass
class Step:
    z: np.ndarray
    tangent: np.ndarray
    ds: float  # the step taken
    ds_next: float
    correction: Correction


def advance(alg, backend, lin, z, t, ds, opts):
    """One accepted step of size <= ds > 0 from (z, t), or None once a step below ds_min failed.
    Refused (retried at ds * alg.shrink) when the corrector fails, moves more than
    alg.max_correction * ds, or turns the tangent by more than acos(alg.min_cos)."""
    while ds >= opts.ds_min:
        z_pred = z + ds * t
        c = correct(backend, lin, z_pred, t, opts.newton_tol, opts.newton_max_iter)
        # a corrector that moved far from the predictor may have landed on a nearby branch
        if c.converged and float(np.linalg.norm(c.z - z_pred)) <= alg.max_correction * ds:
            _, A, a = c.lin
            t_new = tangent(backend, A, a, t)
            if float(t_new @ t) >= alg.min_cos:
                grow = alg.grow if c.iterations <= alg.fast_iterations else 1.0
                return Step(c.z, t_new, ds, min(ds * grow, opts.ds_max), c)
        ds *= alg.shrink
    return None
