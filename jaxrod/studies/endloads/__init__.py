"""Rods under end loads: end shortening, tension and end rotation.

Two ways of loading a rod clamped at both ends along one axis (the clamp at s = 0 fixed; the far
clamp, at s = L, holds its edge along the same axis and its material frame turned by the end
rotation ``phi``):

* **Displacement control** (``shortened_rod``): the far clamp sits L - shortening from the near
  one along the axis (``EndLoadedRod``; ``with_shortening`` is traceable, so the shortening can be
  a continuation parameter). The end loads T = dE/d(end distance) and M = dE/d(phi) are exact by
  autodiff (``end_loads``). Equilibria: ``solve`` and ``solve_from_helix`` (``EndLoadOptions``).
* **Force control** (``ForceLoadedRod``): a dead load T pulls the far clamp along the axis
  (``end="slide"``) or in space (``end="free"``).

Both close the rod with rays along the clamp axis, so Lk = Wr + Tw = Lk0 + phi / 2 pi holds along
any path without strand passage.

Analytic references: the localized helical buckle of Neukirch, van der Heijden and Thompson 2002
(``localized_helix``, where it applies: ``reference_check``), the buckling twist of a straight
rod under tension and the plectoneme's torque plateau (module ``thresholds``).
"""
from .compare import (
    HelixProfiles, choose_helix_root, envelope_error, helix_profiles, helix_root_row, helix_state, relative_error,
    tangent_angles,
)
from .compiled import EIGEN_ROUNDOFF_ULPS, EndLoads, end_loads
from .equilibria import (
    STIFFEN_FACTOR, STIFFEN_FROM, EndLoadOptions, newton, solve, solve_from_helix, stiffening_stages,
)
from .force import ForceEquilibrium, ForceLoadedRod, force_energy, force_hessian, force_zero_modes
from .helix import (
    LOCALIZATION_MIN, STRETCH_SHIFT_MAX, LocalizedHelix, ReferenceCheck, localization_parameter, localized_helix,
    localized_helix_curve, localized_helix_from_shortening, named_helix_roots, nearest_localized_helix,
    reference_check, select_helix_roots, stretch_shift,
)
from .problems import (
    rotation_energy, rotation_jacobian, rotation_problem, shortening_energy, shortening_jacobian, shortening_problem,
)
from .resolution import (
    BEND_RTOL, EDGES_PER_CORE, MAX_TWIST_PER_EDGE, ROUNDOFF_ULPS, check_helix_resolution, check_rotation_resolution,
    coarse_nodes, gradient_tolerance, richardson_extrapolation, tension_roundoff,
)
from .scene import EndLoadedRod, shortened_rod, with_end_offset, with_material, with_shortening
from .shapes import helical_start
from .thresholds import (
    Plectoneme, clamped_tension_twist_threshold, plectoneme_plateau, straight_buckling_moment, tension_twist_threshold,
)

__all__ = [
    "EndLoadedRod",
    "shortened_rod",
    "with_shortening",
    "with_end_offset",
    "end_loads",
    "EndLoads",
    "ForceLoadedRod",
    "ForceEquilibrium",
    "localized_helix",
    "localized_helix_from_shortening",
    "LocalizedHelix",
    "localization_parameter",
    "LOCALIZATION_MIN",
    "reference_check",
    "ReferenceCheck",
    "stretch_shift",
    "gradient_tolerance",
    "with_material",
    "stiffening_stages",
    "solve_from_helix",
    "localized_helix_curve",
    "plectoneme_plateau",
    "Plectoneme",
    "helical_start",
    "straight_buckling_moment",
    "tension_twist_threshold",
    "clamped_tension_twist_threshold",
    "check_helix_resolution",
    "check_rotation_resolution",
    "tangent_angles",
    "envelope_error",
    "named_helix_roots",
    "select_helix_roots",
    "choose_helix_root",
    "nearest_localized_helix",
    "relative_error",
    "tension_roundoff",
    "coarse_nodes",
    "richardson_extrapolation",
    "helix_state",
    "helix_root_row",
    "helix_profiles",
    "HelixProfiles",
    "solve",
    "EndLoadOptions",
    "newton",
]
