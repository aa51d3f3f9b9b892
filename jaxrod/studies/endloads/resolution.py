"""How fine an end-loaded rod must be, and how accurately it can be solved: the nodes a loop and
an end rotation need, Newton's tolerance in the rod's own force units, the roundoff of the
tension, and Richardson's extrapolation in the edge length."""
from __future__ import annotations

import math

import numpy as np

from ...validation import check_int_at_least
from .helix import TWO_PI, localization_parameter
from .scene import check_scene


# below which ``check_helix_resolution`` refuses N: at 6 edges per core the end loads are still O(h^2)
EDGES_PER_CORE = 6.0
# Uniform twist is exact at any angle per edge; pi/2 keeps the material frame's rotation between
# edges well below the half turn at which a drawn stripe aliases.
MAX_TWIST_PER_EDGE = 0.5 * math.pi


def check_rotation_resolution(N, phi):
    """N as an int, or ValueError naming N: an end rotation phi (rad) spread over N - 1 edges needs
    at most ``MAX_TWIST_PER_EDGE`` (pi/2) rad per edge (N >= |phi| / (pi/2) + 2)."""
    N = check_int_at_least("N", N, 5)
    need = math.ceil(abs(float(phi)) / MAX_TWIST_PER_EDGE) + 2
    if N < need:
        raise ValueError(f"N = {N} is too few nodes for the end rotation {float(phi) / TWO_PI:.3g} turns "
                         f"(at most {MAX_TWIST_PER_EDGE} rad of twist per edge): N >= {need}")
    return N


def check_helix_resolution(N, m, t, R):
    """N as an int, or ValueError naming N: the localized helix (m, t) with end rotation R needs
    N - 2 >= 6 lambda edges (6 per core width L / lambda) and at most pi/2 rad of twist per edge."""
    N = check_int_at_least("N", N, 8)
    lam = localization_parameter(m, t)
    need = max(math.ceil(EDGES_PER_CORE * lam), math.ceil(abs(R) / MAX_TWIST_PER_EDGE)) + 2
    if N < need:
        raise ValueError(f"N = {N} is too few nodes for the loop asked (lambda = {lam:.3g}, end rotation "
                         f"{R / TWO_PI:.3g} turns): N >= {need}")
    return N



# Newton's stopping test for a rod under end loads (``gradient_tolerance``): the residual force on
# every node below BEND_RTOL * B/L^2 plus ROUNDOFF_ULPS roundoffs of the stretching and bending forces.
BEND_RTOL = 1e-6
ROUNDOFF_ULPS = 4.0


def gradient_tolerance(scene):
    """Newton's tolerance on the max |gradient| of ``scene``'s scaled energy (``solve``'s default):
    a residual force per node of BEND_RTOL B/L^2 + ROUNDOFF_ULPS eps (L/h) (EA + B/h^2), in the
    scaled gradient's unit B/h^2 (h the edge length, L the clamps' distance): the same relative
    accuracy at every EA, never below the roundoff of the stretching forces."""
    check_scene(scene)
    B, EA = float(scene.material.B), float(scene.material.EA)
    L, h = float(scene.clamp_length), float(scene.length_scale)
    force = BEND_RTOL * B / L ** 2 + ROUNDOFF_ULPS * np.finfo(float).eps * (L / h) * (EA + B / h ** 2)
    return force * h * h / B


def tension_roundoff(N, EA, T):
    """The relative roundoff of the tension T (force) of a rod of N nodes and stretch stiffness
    EA (force): T is EA times a strain, whose roundoff is ~ ``ROUNDOFF_ULPS`` eps (L/h)."""
    return ROUNDOFF_ULPS * np.finfo(float).eps * (N - 2) * EA / max(abs(T), 1e-300)


def coarse_nodes(N):
    """The node count of the rod with edges twice as long as those of N nodes (exactly, for even
    N): the coarse level of ``richardson_extrapolation``."""
    return (N - 2) // 2 + 2


def richardson_extrapolation(fine, coarse, N_fine, N_coarse):
    """Richardson's O(h^2) extrapolation of a quantity (scalar, any units) computed on clamped
    rods of N_fine and N_coarse nodes (edge length h = L / (N - 2)): (r^2 fine - coarse) / (r^2 - 1),
    r = h_coarse / h_fine."""
    r2 = ((N_fine - 2) / (N_coarse - 2)) ** 2
    return (r2 * fine - coarse) / (r2 - 1.0)
