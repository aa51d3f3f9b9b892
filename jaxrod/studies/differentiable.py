"""Critical twists as JAX-differentiable functions of a scene's continuous parameters.

``critical_twist_function(scene, side, parameters)`` returns ``f(values) -> phi*``, a function that
``jax.grad``, ``jax.jacfwd``, ``jax.jvp``, ``jax.jit`` and ``jax.vmap`` go through:

- its value is the end that ``critical_twists`` locates on the scene with those parameter values
  (``scene.with_params``), computed on the host by the library's own solvers (``jax.pure_callback``);
- its derivative is exact, by the implicit function theorem at the located end
  (``critical_twist_sensitivity``: on the crossing eigenvalue for rings and clamped rods, on the fold
  system for knots), attached with ``jax.custom_jvp``; no finite difference and no differentiation
  through the solver's iterations.

What the derivative means: for a ring or a clamped rod, the derivative of the twist at which the
trivial (symmetric) branch's critical eigenvalue crosses zero (at Michell's double branch point,
that branch's); for a knot, the fold's. Second derivatives are not available (the sensitivity is a
host value). ``match_critical_twist`` uses the exact derivative for design: the parameter value that
puts an end at a target twist, by Newton's method.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .critical_ends import critical_twist_sensitivity, is_knot, knot_ends, parameter_value, ring_end

__all__ = ["critical_twist_function", "match_critical_twist", "DesignResult", "Measurement", "FitResult", "fit_critical_twists"]

SIDES = ("plus", "minus")


def _end_solver(scene, side, names, phi_min, phi_max, options):
    """solve(values: tuple of floats) -> (phi*, d phi*/d values (k,)): one side's end located on the
    host and its exact sensitivities; the last 64 kept (a value and its derivative come from one
    location). ValueError for an unknown side."""
    if side not in SIDES:
        raise ValueError(f"side must be 'plus' or 'minus', got {side!r}")

    @functools.lru_cache(maxsize=64)
    def solve(values):
        rod = scene.with_params(**dict(zip(names, values)))
        if is_knot(rod):  # a knot's twist study runs both sides; the other may end out of range
            end = knot_ends(rod, phi_min, phi_max, options).get(side)
            if end is None:
                raise RuntimeError(f"no branch end on the {side} side between {phi_min / math.pi:+.4f} pi and "
                                   f"{phi_max / math.pi:+.4f} pi (at {dict(zip(names, values))})")
        else:  # a ring or a clamped rod: this side only
            end = ring_end(rod, side, phi_max if side == "plus" else phi_min, options)
        slope = [critical_twist_sensitivity(rod, end, name) for name in names]
        return float(end.phi), np.asarray(slope, dtype=np.float64)

    return solve


def critical_twist_function(scene, side, parameters, phi_min=-8.0 * math.pi, phi_max=8.0 * math.pi, options=None):
    """phi* of one side as a differentiable function of some of the scene's parameters.

    Parameters
    ----------
    scene : ClosedRod or ClampedRod
        The rod at the base values; its other parameters, geometry and terms stay fixed.
    side : str
        'plus' (the end found twisting up from phi = 0) or 'minus'.
    parameters : sequence of str
        Names in ``scene.PARAMETERS`` ('B', 'C', 'EA', 'D', 'nu', 'contact_stiffness'), in the order
        of ``values``.
    phi_min, phi_max, options
        As for ``critical_twists``.

    Returns
    -------
    callable
        ``f(values)`` with values (k,) -> phi* (scalar, rad), float64. ``f.base`` holds the scene's
        own values (k,), a starting point.

    Raises
    ------
    ValueError
        An unknown side or parameter, or no parameter. Evaluating f raises what ``critical_twists``
        raises (no end in the range), and ValueError for a knot's end that is not a fold.
    """
    names = (parameters,) if isinstance(parameters, str) else tuple(parameters)
    if not names:
        raise ValueError("parameters: name at least one of " + ", ".join(scene.PARAMETERS))
    solve = _end_solver(scene, side, names, phi_min, phi_max, options)
    base = np.array([parameter_value(scene, name) for name in names])  # ValueError for an unknown name

    def host(values):
        phi, slope = solve(tuple(float(v) for v in np.asarray(values, dtype=np.float64)))
        return np.float64(phi), slope

    shapes = (jax.ShapeDtypeStruct((), jnp.float64), jax.ShapeDtypeStruct((len(names),), jnp.float64))

    def located(values):
        values = jnp.asarray(values, jnp.float64)
        if values.shape != (len(names),):
            raise ValueError(f"values must have shape ({len(names)},), one per parameter {names}; got {values.shape}")
        return jax.pure_callback(host, shapes, values, vmap_method="sequential")

    @jax.custom_jvp
    def phi_star(values):
        return located(values)[0]

    @phi_star.defjvp
    def _phi_star_jvp(primals, tangents):
        phi, slope = located(primals[0])
        return phi, jnp.dot(slope, jnp.asarray(tangents[0], jnp.float64))

    phi_star.base = base
    phi_star.parameters = names
    return phi_star


@dataclass(frozen=True)
class DesignResult:
    """value: the parameter value found; phi: phi* there (rad); target (rad); converged: |phi - target|
    <= tol; iterations: Newton steps; residual: phi - target (rad); reason: why it stopped."""

    value: float
    phi: float
    target: float
    converged: bool
    iterations: int
    residual: float
    reason: str


def match_critical_twist(scene, side, parameter, target, tol=1e-8, max_iterations=20, phi_min=-8.0 * math.pi,
                         phi_max=8.0 * math.pi, options=None):
    """The value of one parameter that puts a critical twist at ``target``.

    Newton's method on phi*(p) - target with the exact derivative (as ``critical_twist_function``
    has it), from the scene's own value; a step that does not reduce |phi* - target| is halved, up
    to 8 times (a trial outside the parameter's range, or with no end in the range, counts as not
    reducing it).

    Parameters
    ----------
    scene : ClosedRod or ClampedRod
        The rod at its starting value.
    side : str
        'plus' or 'minus'.
    parameter : str
        One name in ``scene.PARAMETERS``.
    target : float
        The critical twist wanted (rad).
    tol : float, optional
        Stop when |phi* - target| <= tol (rad).
    max_iterations : int, optional
        Newton steps at most.
    phi_min, phi_max, options
        As for ``critical_twists``.

    Returns
    -------
    DesignResult
        value, phi, target, converged, iterations, residual (phi - target, rad), reason.

    Raises
    ------
    ValueError
        tol <= 0, max_iterations < 1, an unknown side or parameter.
    """
    if not tol > 0.0:
        raise ValueError(f"tol must be > 0 (rad), got {tol!r}")
    if int(max_iterations) < 1:
        raise ValueError(f"max_iterations must be >= 1, got {max_iterations!r}")
    solve = _end_solver(scene, side, (parameter,), phi_min, phi_max, options)

    def value_and_slope(value):
        phi, slope = solve((float(value),))
        return phi, float(slope[0])

    p = parameter_value(scene, parameter)  # ValueError for an unknown name
    phi, slope = value_and_slope(p)
    for it in range(int(max_iterations) + 1):
        residual = phi - target
        if abs(residual) <= tol:
            return DesignResult(p, phi, target, True, it, residual, f"|phi* - target| <= tol = {tol:.1e} rad")
        if it == int(max_iterations):
            break
        if slope == 0.0 or not math.isfinite(slope):
            return DesignResult(p, phi, target, False, it, residual, f"d phi*/d {parameter} is {slope}: no Newton step")
        step, failure = -residual / slope, ""
        for _ in range(8):
            try:
                phi_new, slope_new = value_and_slope(p + step)
            except (ValueError, RuntimeError) as exc:  # out of the parameter's range, or no end in the range
                phi_new, failure = math.nan, f" (the last trial, {parameter} = {p + step:.6g}: {exc})"
            if abs(phi_new - target) < abs(residual):
                break
            step *= 0.5
        else:
            return DesignResult(p, phi, target, False, it, residual,
                                "no step along the Newton direction reduced the misfit" + failure)
        p, phi, slope = p + step, phi_new, slope_new
    return DesignResult(p, phi, target, False, int(max_iterations), phi - target,
                        f"max_iterations = {max_iterations} reached")


@dataclass(frozen=True)
class Measurement:
    """One measured critical twist: the rod it was measured on (its scene, at the starting values of
    the fitted parameters), the side ('plus' or 'minus'), phi (rad) and its standard error sigma (rad)."""

    scene: object
    side: str
    phi: float
    sigma: float


@dataclass(frozen=True)
class FitResult:
    """values (k,): the fitted parameters; standard_errors (k,): from the exact Jacobian J of the
    weighted residuals, sqrt(diag((J^T J)^-1)) (the sigmas taken as given, no rescaling); residuals
    (m,): phi*_i - phi_i (rad) at the fit; chi2: the sum of the squared weighted residuals;
    converged, iterations (model evaluations), reason: from SciPy's least_squares."""

    parameters: tuple
    values: np.ndarray
    standard_errors: np.ndarray
    residuals: np.ndarray
    chi2: float
    converged: bool
    iterations: int
    reason: str


def fit_critical_twists(measurements, parameters, start=None, phi_min=-16.0 * math.pi, phi_max=16.0 * math.pi,
                        options=None):
    """Fit scene parameters to measured critical twists by weighted least squares.

    Each measurement's model is ``critical_twist_function(m.scene, m.side, parameters)``; the
    residuals (phi*_i(p) - phi_i) / sigma_i are minimised by SciPy's ``least_squares`` (trust-region
    reflective) with the exact Jacobian (the implicit function theorem at each located end).

    Parameters
    ----------
    measurements : sequence of Measurement
        At least as many as parameters; sigma > 0.
    parameters : sequence of str
        Names in the scenes' ``PARAMETERS``, shared by every measurement.
    start : array_like (k,), optional
        Starting values (default: the first measurement's scene's own values).
    phi_min, phi_max, options
        As for ``critical_twists``, for every measurement.

    Returns
    -------
    FitResult

    Raises
    ------
    ValueError
        No measurement, fewer measurements than parameters, a sigma that is not > 0, or a start of
        the wrong length.
    """
    from scipy.optimize import least_squares

    names = (parameters,) if isinstance(parameters, str) else tuple(parameters)
    ms = tuple(measurements)
    if not ms or len(ms) < len(names):
        raise ValueError(f"measurements: need at least {len(names)} (one per parameter), got {len(ms)}")
    if not all(float(m.sigma) > 0.0 for m in ms):
        raise ValueError("measurements: every sigma must be > 0 (rad)")
    fns = [critical_twist_function(m.scene, m.side, names, phi_min, phi_max, options) for m in ms]
    x0 = np.asarray(fns[0].base if start is None else start, dtype=float)
    if x0.shape != (len(names),):
        raise ValueError(f"start must have {len(names)} values, one per parameter {names}; got shape {x0.shape}")
    sigma = np.array([float(m.sigma) for m in ms])
    phi = np.array([float(m.phi) for m in ms])
    models = [jax.value_and_grad(f) for f in fns]

    def evaluate(x):
        pairs = [model(jnp.asarray(x)) for model in models]
        return np.array([float(v) for v, _ in pairs]), np.array([np.asarray(g) for _, g in pairs])

    sol = least_squares(lambda x: (evaluate(x)[0] - phi) / sigma, x0, jac=lambda x: evaluate(x)[1] / sigma[:, None],
                        method="trf", x_scale="jac")
    values, jac = evaluate(sol.x)
    weighted = jac / sigma[:, None]
    errors = np.sqrt(np.diag(np.linalg.pinv(weighted.T @ weighted)))
    return FitResult(names, sol.x, errors, values - phi, float(np.sum(((values - phi) / sigma) ** 2)),
                     bool(sol.success), int(sol.nfev), str(sol.message))
