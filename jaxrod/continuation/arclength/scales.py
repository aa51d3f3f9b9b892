"""The pseudo-arclength tolerances a problem's own scale sets: Newton's, the located events', and
the negative band of the Morse count, for the ones a ``ContinuationOptions`` leaves None.

In float64 the residual F = grad_u E cannot be computed below a roundoff floor that grows with the
problem's stiffest term (a rod's stretching, EA l^2/B = 16 (l/D)^2 in scaled units), so fixed
tolerances can lie below it and a band relative to ||J|| can be wider than the bending eigenvalues.
The rule, with x = max(|u|_2, 1) and eps the machine epsilon:

    floor      = eps ||J||_2 x                                   (``residual_floor``)
    newton_tol = max(NEWTON_TOL, NEWTON_FLOOR_FACTOR floor)
    event_tol  = max(EVENT_TOL, EVENT_FLOOR_FACTOR floor)
    eig_rtol   = max(EIG_NOISE_FACTOR eps, EIG_RTOL min(1, 1 / ||J||_2))

so that a well-scaled problem keeps the fixed values and a stiff one gets tolerances above its
floor. J is evaluated once, at the start of a run.
"""
from __future__ import annotations

import numpy as np

from ..options import checked_options

EPS = float(np.finfo(float).eps)
NEWTON_TOL = 1e-12
EVENT_TOL = 1e-10
EIG_RTOL = 1e-10
NEWTON_FLOOR_FACTOR = 0.5
EVENT_FLOOR_FACTOR = 4.0
EIG_NOISE_FACTOR = 100.0
SCALED = ("newton_tol", "event_tol", "eig_rtol")
# Power iterations for ||J||_2 (an estimate from below; only its order of magnitude counts).
NORM_ITERATIONS = 30


def operator_norm(J, iterations=NORM_ITERATIONS):
    """||J||_2 of the symmetric J (a dense array or a ``HostMatrix``), by power iteration from a
    fixed start vector (deterministic)."""
    matvec = J.matvec if hasattr(J, "matvec") else (lambda x, A=np.asarray(J, dtype=float): A @ x)
    x = np.cos(0.7 * np.arange(J.shape[0]) + 0.3) + 0.5
    x /= np.linalg.norm(x)
    norm = 0.0
    for _ in range(iterations):
        y = np.asarray(matvec(x), dtype=float)
        norm = float(np.linalg.norm(y))
        if not (np.isfinite(norm) and norm > 0.0):
            break
        x = y / norm
    return norm


def residual_floor(problem, u, p):
    """(floor, ||J||_2): the roundoff floor eps ||J||_2 max(|u|_2, 1) of the residual |F(u, p)|
    (an upper estimate, see the module docstring), and ||J||_2 at (u, p)."""
    _, J, _ = problem.linearise(np.asarray(u, dtype=float), float(p), problem.args)
    norm = operator_norm(J)
    return EPS * norm * max(float(np.linalg.norm(np.asarray(u, dtype=float))), 1.0), norm


def scaled_tolerances(problem, u, p):
    """{"newton_tol", "event_tol", "eig_rtol"} the problem's scale sets at (u, p) (module docstring)."""
    floor, norm = residual_floor(problem, u, p)
    return {"newton_tol": max(NEWTON_TOL, NEWTON_FLOOR_FACTOR * floor),
            "event_tol": max(EVENT_TOL, EVENT_FLOOR_FACTOR * floor),
            "eig_rtol": max(EIG_NOISE_FACTOR * EPS, EIG_RTOL * min(1.0, 1.0 / norm) if norm > 0 else EIG_RTOL)}


def scaled_options(problem, options, u, p):
    """``options`` (None: the defaults) resolved for pseudo-arclength continuation of ``problem``,
    newton_tol, event_tol and eig_rtol left None set by ``scaled_tolerances`` at (u, p)."""
    options = checked_options(options)
    missing = [key for key in SCALED if getattr(options, key) is None]
    if missing:
        scaled = scaled_tolerances(problem, u, p)
        options = options.updated(**{key: scaled[key] for key in missing})
    return options.resolved_arclength()
