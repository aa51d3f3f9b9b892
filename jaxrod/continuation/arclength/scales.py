"""The pseudo-arclength tolerances a problem's own scale sets: Newton's, the located events', and
the negative band of the Morse count, for the ones a ``ContinuationOptions`` leaves None.

Why: in float64 the residual F(u, p) = grad_u E cannot be computed more precisely than its roundoff
floor, which grows with the stiffest term of the problem, not with the quantity followed. A rod
in scaled units (coordinates in edge lengths, energy in B/l) has its stretching stiffness EA l^2/B
= 16 (l/D)^2 in J: ||J||_2 ~ 6e3 for Michell's ring at N = 64, D/R = 0.01, and 16 times that at
D/R = 0.0025. Fixed tolerances (1e-12 on the residual, 1e-10 on a located event) then lie below the
floor (Newton never converges), and a band of 1e-10 ||J|| on the eigenvalues is wider than the
bending-scale eigenvalues it must resolve. The rule, with x = max(|u|_2, 1) and eps the machine
epsilon:

    floor      = eps ||J||_2 x                                   (``residual_floor``)
    newton_tol = max(NEWTON_TOL, NEWTON_FLOOR_FACTOR floor)
    event_tol  = max(EVENT_TOL, EVENT_FLOOR_FACTOR floor)
    eig_rtol   = max(EIG_NOISE_FACTOR eps, EIG_RTOL min(1, 1 / ||J||_2))

so that a well-scaled problem (||J|| x below ~1e4, ||J|| <= 1) keeps the fixed values exactly, and
a stiff one gets tolerances above its floor. The floor estimate is an upper bound of the measured
one: the stretching force of an edge carries a roundoff of ~eps EA |x_i| (coordinates of size
|x_i|), summed over n rows, which eps ||J|| |u|_2 bounds. Measured on Michell's pinned ring (Newton
with p fixed, 12 to 19 iterations past convergence, the circle at phi = 0, phi*/2 and 0.99 phi*, and along
the buckled branch to self-contact): the largest residual over the estimate is 0.17 (N = 16), 0.13
(N = 32), 0.13 (N = 64), the same at D/R = 0.01, 0.005 and 0.0025 (the floor itself scales with
1/D^2: 1.1e-11, 4.6e-11, 1.9e-10 at N = 64); the residual of the located double branch point is at
most 0.20 of it (N = 16, 24, 32, 48, 64 at D/R = 0.0025). Hence NEWTON_FLOOR_FACTOR = 0.5 (3x the
largest measured floor: 5.5e-11 at N = 64, D/R = 0.01) and
EVENT_FLOOR_FACTOR = 4 (20x the located residual).

The negative band: eigenvalues computed from J carry a roundoff of ~eps ||J|| (the located critical
eigenvalues, zero in exact arithmetic, are at most 0.2 eps ||J|| on the ring), so a band of
EIG_NOISE_FACTOR = 100 eps ||J|| is 500 times that noise; above it, an eigenvalue counts as
negative below -EIG_RTOL in the problem's units, as ``linalg.tolerances.DEFAULT_NEGATIVE_TOL`` does
for the stable-only engine (and, for ||J|| < 1, below -EIG_RTOL ||J||). A relative band of 1e-10
would lie at 1e-5 on the ring at D/R = 0.0025, above the buckled branch's negative eigenvalue next
to the branch point (-4e-8 at its first point): the Morse index would read 0 there and 1 further
on, a false branch point.

J is evaluated once, at the start of a run (u, p): ||J|| and |u| change by a few percent along the
ring's branches (measured: the estimate goes from 2.4e-9 to 1.7e-9 between the branch point and
self-contact at D/R = 0.0025, N = 64).
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
# Power iterations for ||J||_2: an estimate from below, within a few percent on a rod's Hessian
# (its largest eigenvalues, the stretching modes, are clustered); only its order of magnitude counts.
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
    """{"newton_tol", "event_tol", "eig_rtol"}: the defaults the problem's scale sets at (u, p),
    by the rule of the module docstring."""
    floor, norm = residual_floor(problem, u, p)
    return {"newton_tol": max(NEWTON_TOL, NEWTON_FLOOR_FACTOR * floor),
            "event_tol": max(EVENT_TOL, EVENT_FLOOR_FACTOR * floor),
            "eig_rtol": max(EIG_NOISE_FACTOR * EPS, EIG_RTOL * min(1.0, 1.0 / norm) if norm > 0 else EIG_RTOL)}


def scaled_options(problem, options, u, p):
    """``options`` (a ``ContinuationOptions``, None: the defaults) resolved for pseudo-arclength
    continuation of ``problem``, newton_tol, event_tol and eig_rtol left None set by
    ``scaled_tolerances`` at (u, p); values given are kept. Resolved options come back unchanged
    (nothing is evaluated)."""
    options = checked_options(options)
    missing = [key for key in SCALED if getattr(options, key) is None]
    if missing:
        scaled = scaled_tolerances(problem, u, p)
        options = options.updated(**{key: scaled[key] for key in missing})
    return options.resolved_arclength()
