"""Design and calibration from differentiable critical twists (``jaxrod.studies.differentiable``).

- ``match_critical_twist``: the value of one parameter that puts an end at a target twist, by
  Newton's method with the exact derivative;
- ``maximise_twist_window``: the parameter values in a box that widen the stable window
  phi*+ - phi*- the most, by L-BFGS-B (SciPy) with the exact gradient;
- ``fit_critical_twists``: scene parameters fitted to measured onsets by weighted least squares
  (SciPy's ``least_squares``, trust-region reflective, with the exact Jacobian), with standard
  errors from that Jacobian.

SciPy's bounded optimisers are used rather than hand-written loops: they are well kept, handle
bounds, and report why they stopped.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .critical_ends import parameter_value
from .differentiable import critical_twist_function

__all__ = ["match_critical_twist", "DesignResult", "maximise_twist_window", "WindowResult", "Measurement", "FitResult",
           "fit_critical_twists"]


def _value_and_gradient(f):
    """(values (k,) numpy) -> (phi*, d phi*/d values (k,)) on the host, through one compiled program."""
    program = jax.jit(jax.value_and_grad(f))

    def evaluate(values):
        phi, grad = program(jnp.asarray(values, jnp.float64))
        return float(phi), np.asarray(grad, dtype=float)

    return evaluate


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
    p = parameter_value(scene, parameter)  # ValueError for an unknown name
    evaluate = _value_and_gradient(critical_twist_function(scene, side, (parameter,), phi_min, phi_max, options))

    def value_and_slope(value):
        phi, slope = evaluate([value])
        return phi, float(slope[0])

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
                why = str(exc).strip().splitlines()[-1]  # through a callback, the last line is the host's error
                phi_new, failure = math.nan, f" (the last trial, {parameter} = {p + step:.6g}: {why})"
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
class WindowResult:
    """parameters: names; values (k,): where the window is widest in the box; window: phi*+ - phi*-
    there (rad), with plus and minus (rad); gradient (k,): d window / d values there (rad per unit);
    at_bound (k,) bool: the value sits on its bound; converged, iterations (evaluations), reason:
    from SciPy's L-BFGS-B."""

    parameters: tuple
    values: np.ndarray
    window: float
    plus: float
    minus: float
    gradient: np.ndarray
    at_bound: np.ndarray
    converged: bool
    iterations: int
    reason: str


def maximise_twist_window(scene, parameters, bounds, start=None, phi_min=-16.0 * math.pi, phi_max=16.0 * math.pi,
                          options=None):
    """The parameter values in a box that make the stable twist window phi*+ - phi*- widest.

    The window is the range of twist over which the branch from phi = 0 stays stable. It is
    maximised by SciPy's L-BFGS-B with its exact gradient (``critical_twist_function`` on both
    sides; a knot's two ends come from one twist study and are then followed in the parameters).

    Parameters
    ----------
    scene : ClosedRod or ClampedRod
        The rod at the starting values.
    parameters : sequence of str
        Names in ``scene.PARAMETERS``.
    bounds : sequence of (low, high)
        One pair per parameter, inside the parameter's range.
    start : array_like (k,), optional
        Starting values (default: the scene's own, which must lie in the box).
    phi_min, phi_max, options
        As for ``critical_twists``.

    Returns
    -------
    WindowResult

    Raises
    ------
    ValueError
        An unknown parameter, bounds of the wrong length or with low >= high, or a start outside them.
    """
    from scipy.optimize import minimize

    names = (parameters,) if isinstance(parameters, str) else tuple(parameters)
    box = np.asarray(bounds, dtype=float).reshape(-1, 2) if len(bounds) else np.zeros((0, 2))
    if box.shape != (len(names), 2) or not np.all(box[:, 0] < box[:, 1]):
        raise ValueError(f"bounds must give (low, high) with low < high for each of {names}; got {bounds!r}")
    x0 = np.array([parameter_value(scene, n) for n in names]) if start is None else np.asarray(start, dtype=float)
    if x0.shape != (len(names),) or np.any(x0 < box[:, 0]) or np.any(x0 > box[:, 1]):
        raise ValueError(f"start {x0.tolist()} must have one value per parameter {names}, inside the bounds")
    sides = [_value_and_gradient(f) for f in _models([Measurement(scene, side, 0.0, 1.0) for side in ("plus", "minus")],
                                                      names, phi_min, phi_max, options)]

    def negative_window(x):
        (plus, g_plus), (minus, g_minus) = (side(x) for side in sides)
        return minus - plus, g_minus - g_plus

    sol = minimize(negative_window, x0, jac=True, method="L-BFGS-B", bounds=box)
    (plus, g_plus), (minus, g_minus) = (side(sol.x) for side in sides)
    span = box[:, 1] - box[:, 0]
    at_bound = (np.abs(sol.x - box[:, 0]) <= 1e-9 * span) | (np.abs(sol.x - box[:, 1]) <= 1e-9 * span)
    return WindowResult(names, np.asarray(sol.x), plus - minus, plus, minus, g_plus - g_minus, at_bound,
                        bool(sol.success), int(sol.nfev), str(sol.message))


@dataclass(frozen=True)
class Measurement:
    """One measured critical twist: the rod it was measured on (its scene, at the starting values of
    the fitted parameters), the side ('plus' or 'minus'), phi (rad) and its standard error sigma
    (rad); end: for a knot, the model's end on that side from ``critical_twists(scene)`` if already
    located (else it is located by the fit)."""

    scene: object
    side: str
    phi: float
    sigma: float
    end: object = None


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


def _models(measurements, names, phi_min, phi_max, options):
    """critical_twist_function for each measurement; a knot's two sides located by one twist study."""
    from .critical_ends import is_knot, knot_ends

    located = {}
    for m in measurements:
        if m.end is None and is_knot(m.scene) and id(m.scene) not in located:
            located[id(m.scene)] = knot_ends(m.scene, phi_min, phi_max, options)
    return [critical_twist_function(m.scene, m.side, names, phi_min, phi_max, options,
                                    end=m.end if m.end is not None else located.get(id(m.scene), {}).get(m.side))
            for m in measurements]


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
    fns = _models(ms, names, phi_min, phi_max, options)
    x0 = np.asarray(fns[0].base if start is None else start, dtype=float)
    if x0.shape != (len(names),):
        raise ValueError(f"start must have {len(names)} values, one per parameter {names}; got shape {x0.shape}")
    sigma = np.array([float(m.sigma) for m in ms])
    phi = np.array([float(m.phi) for m in ms])
    models = [_value_and_gradient(f) for f in fns]

    def evaluate(x):
        pairs = [model(x) for model in models]
        return np.array([v for v, _ in pairs]), np.array([g for _, g in pairs])

    sol = least_squares(lambda x: (evaluate(x)[0] - phi) / sigma, x0, jac=lambda x: evaluate(x)[1] / sigma[:, None],
                        method="trf", x_scale="jac")
    values, jac = evaluate(sol.x)
    weighted = jac / sigma[:, None]
    errors = np.sqrt(np.diag(np.linalg.pinv(weighted.T @ weighted)))
    return FitResult(names, sol.x, errors, values - phi, float(np.sum(((values - phi) / sigma) ** 2)),
                     bool(sol.success), int(sol.nfev), str(sol.message))
