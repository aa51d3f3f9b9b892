"""Input checks shared by the API and the CLI: each raises ``ValueError`` naming the parameter.

The checks of continuous parameters let jax tracers through (``jax.grad``, ``jax.jvp``,
``jax.vmap`` and ``jax.jit`` over a scene's constructor): a tracer's value is unknown, so only its
shape and dtype are checked, and it is returned as it is. A concrete value is checked and returned
as a Python number. Parameters that set array shapes or other static structure (node counts,
linking numbers) must be concrete: ``require_concrete`` names them when a tracer reaches them.
"""
from __future__ import annotations

import math
import sys

__all__ = ["parse_angle_text", "check_finite", "check_positive", "check_int_at_least", "check_poisson_ratio", "check_points",
           "refuse_knot", "is_traced", "require_concrete"]


def is_traced(value):
    """Whether ``value`` is a jax tracer (an abstract value inside jax.grad/jvp/vmap/jit)."""
    # jax is not imported for this: a value cannot be a tracer before jax is loaded, and the CLI
    # checks its arguments before it loads jax
    jax = sys.modules.get("jax")
    return jax is not None and isinstance(value, jax.core.Tracer)


def require_concrete(name, value, why):
    """Raise ValueError naming ``name`` if ``value`` is a jax tracer; ``why`` says what the value
    decides (array shapes, a branch) so that it cannot be traced."""
    if is_traced(value):
        raise ValueError(f"{name} must be a concrete value, not a jax tracer: {why}; build the scene outside "
                         f"the traced function or close over {name} (make it static)")
    return value


def _checked_tracer(name, value):
    """A traced real scalar as it is (its value cannot be checked), else ValueError naming ``name``."""
    import numpy as np

    shape, dtype = getattr(value, "shape", None), getattr(value, "dtype", None)
    real = dtype is not None and (np.issubdtype(dtype, np.floating) or np.issubdtype(dtype, np.integer))
    if shape != () or not real:
        raise ValueError(f"{name} must be a real number, got a traced array of shape {shape} and dtype {dtype}")
    return value


def check_finite(name, value):
    """Raise ValueError naming ``name`` unless ``value`` is a finite real number; a jax tracer
    passes when it is a real scalar (returned as it is)."""
    if is_traced(value):
        return _checked_tracer(name, value)
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def check_positive(name, value):
    """Raise ValueError naming ``name`` unless ``value`` is finite and > 0 (a tracer: see check_finite)."""
    v = check_finite(name, value)
    if is_traced(v):
        return v
    if v <= 0.0:
        raise ValueError(f"{name} must be positive, got {value!r}")
    return v


def check_int_at_least(name, value, minimum):
    """Raise ValueError naming ``name`` unless ``value`` is an integer >= minimum (an int, or a
    float or numpy number with an integer value; not a bool, a string or None). It sets shapes or
    counts, so a jax tracer is refused."""
    require_concrete(name, value, "an integer parameter sets static structure (array shapes, counts, a linking number)")
    try:
        whole = not isinstance(value, (bool, str, bytes)) and int(value) == value
    except (TypeError, ValueError, OverflowError):  # None, nan, inf, objects
        whole = False
    if not whole:
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if int(value) < minimum:
        raise ValueError(f"{name} must be at least {minimum}, got {value!r}")
    return int(value)


def check_poisson_ratio(name, value):
    """Raise ValueError naming ``name`` unless ``value`` lies in (-1, 0.5], the range of an
    isotropic material's Poisson ratio (B/C = 1 + nu must stay positive); a tracer: see check_finite."""
    nu = check_finite(name, value)
    if is_traced(nu):
        return nu
    if not (-1.0 < nu <= 0.5):
        raise ValueError(f"{name} must lie in (-1, 0.5], got {value!r}")
    return nu


def check_points(name, points, finite=False):
    """``points`` as a float array of shape (N, 3) with N >= 2, else ValueError naming ``name``;
    with ``finite``, also refuse NaN and infinities."""
    import numpy as np

    a = np.asarray(points, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] < 2:
        raise ValueError(f"{name} must have shape (N, 3) with N >= 2, got {a.shape}")
    if finite and not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite")
    return a


def refuse_knot(scene, what):
    """Raise ValueError for a knot (a closed rod with self-contact) given to ``what``: an analysis by
    the stable branch's linearisation that gives wrong answers there, without a warning.

    A loose knot has near-null sliding modes (strands slipping, ~1e-11 to 1e-7 in scaled units, of
    either sign), which a negative count takes for an instability (measured: ``critical_twist`` on
    the trefoil at N = 61 returned 2.5411 pi, a slide, in place of the fold at 6.60 pi); and a
    knot's branch end is a fold, where the derivative of the fixed-branch linearisation is the
    wrong formula (it depended on tol, and disagreed with finite differences of studies)."""
    # told by the scene's attributes, not its class: this module sits below .scenes (no import cycle)
    if getattr(scene, "closed", False) and "contact" in getattr(scene, "terms", ()):
        raise ValueError(
            f"{what} does not handle knots (a closed rod with self-contact): their sliding modes are taken "
            "for instabilities and their branch ends are folds. Locate a knot's branch ends with "
            "follow_twist / twist_study, or exactly with jaxrod.continuation.arclength.rods.knot_problem and "
            "jaxrod.continuation.arclength.continuation (folds of the extended system); the derivative of a fold's phi* "
            "with jaxrod.continuation.arclength.fold_sensitivity")


def parse_angle_text(text, name):
    """An angle in radians from '6.5pi', '-8*pi', 'pi' or a plain number; ValueError naming ``name``."""
    s = str(text).strip().lower().replace(" ", "")
    try:
        if s.endswith("pi"):
            head = s[:-2].rstrip("*")
            return (1.0 if head in ("", "+") else -1.0 if head == "-" else float(head)) * math.pi
        return float(s)
    except ValueError:
        raise ValueError(f"{name}: not an angle: {text!r} (use e.g. 12pi or 3.7)") from None
