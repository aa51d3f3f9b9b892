"""Material of a circular, isotropic, naturally straight elastic rod."""
from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import numpy as np

from ..validation import check_finite, check_int_at_least, check_poisson_ratio, check_positive

__all__ = ["Material"]


@dataclass(frozen=True, eq=False)
class Material:
    """Stiffnesses of the rod.

    For a circular isotropic rod, ``Material.from_engineering(E, nu, D)`` gives B = E pi D^4/64,
    C = B/(1+nu), EA = E pi D^2/4; ``Material.from_ratio(B, nu, D)`` sets EA = 16 B/D^2. Units are
    the caller's: E in MPa (N/mm^2) with D in mm gives B in N mm^2.

    Each parameter may be a jax tracer (``jax.grad``/``jax.jvp``/``jax.vmap`` over a function that
    builds the material): a concrete value is checked and kept as a float, a traced one is
    checked only for being a real scalar.

    Parameters
    ----------
    B : float
        Bending stiffness E I (force x length^2, e.g. N mm^2), > 0.
    C : float
        Twist stiffness G J (same units as B), > 0.
    EA : float
        Stretching stiffness (force, e.g. N), > 0.
    D : float, optional
        Rod diameter (length, e.g. mm), > 0; self-contact and slenderness need it.

    Attributes
    ----------
    nu : float
        Poisson ratio implied by B/C = 1 + nu.

    Raises
    ------
    ValueError
        A concrete parameter that is not a positive finite number (the message names it).
    """

    B: float
    C: float
    EA: float
    D: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "B", check_positive("B", self.B))
        object.__setattr__(self, "C", check_positive("C", self.C))
        object.__setattr__(self, "EA", check_positive("EA", self.EA))
        if self.D is not None:
            object.__setattr__(self, "D", check_positive("D", self.D))

    @classmethod
    def from_engineering(cls, E, nu, D):
        """From Young's modulus E, Poisson ratio nu in (-1, 0.5] and diameter D."""
        E = check_positive("E", E)
        D = check_positive("D", D)
        nu = check_poisson_ratio("nu", nu)
        B = E * math.pi * D**4 / 64.0
        return cls(B=B, C=B / (1.0 + nu), EA=E * math.pi * D**2 / 4.0, D=D)

    @classmethod
    def from_ratio(cls, B, nu, D):
        """Bending stiffness B, Poisson ratio nu and diameter D (EA = 16 B / D^2, C = B/(1+nu))."""
        B = check_positive("B", B)
        D = check_positive("D", D)
        nu = check_poisson_ratio("nu", nu)
        return cls(B=B, C=B / (1.0 + nu), EA=16.0 * B / D**2, D=D)

    @property
    def nu(self):
        """Poisson ratio implied by B/C = 1 + nu."""
        return self.B / self.C - 1.0


def strong_leaf(value):
    """A pytree leaf as jit should key it: a Python float as a float64 scalar, a weakly typed array
    as a float64 one, anything else (tracers included) unchanged. jit keys weak and strong types
    apart, so a scene built from Python floats and the same scene with numpy values (loaded, or set
    by ``with_params``) would otherwise compile every program twice."""
    if type(value) is float:
        return np.float64(value)
    if isinstance(value, jax.Array) and not isinstance(value, jax.core.Tracer) and value.weak_type:
        return value.astype(value.dtype)
    return value


def _flatten_material(m):
    return tuple(strong_leaf(v) for v in (m.B, m.C, m.EA, m.D)), None


def _unflatten_material(_, children):
    # Bypass __init__: leaves may be tracers, which validation cannot (and need not) check.
    m = object.__new__(Material)
    for name, v in zip(("B", "C", "EA", "D"), children):
        object.__setattr__(m, name, v)
    return m


jax.tree_util.register_pytree_node(Material, _flatten_material, _unflatten_material)
