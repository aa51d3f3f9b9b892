"""Eigenvalue tolerances shared by the stability analyses (dense and O(N)): in the lowest layer, so
that ``stability``, ``sparse_stability`` and ``sparse_contact`` all import them from below."""

# An eigenvalue counts as negative below -DEFAULT_NEGATIVE_TOL (dimensionless units). Well below
# the softest physical mode of the rods studied (>1e-7 for N <= 512 rings), above round-off.
DEFAULT_NEGATIVE_TOL = 1e-10
# Near-zero modes of a loose knot (strands sliding) sit at |lambda| ~ 1e-7 and change sign from step
# to step: with self-contact an eigenvalue counts as negative only beyond this.
CONTACT_NEGATIVE_TOL = 1e-6

# Long rods: their softest modes go like N^-4 in the scaled units (the bending scale (2 pi l / L)^4),
# so past N ~ 600 the strict tolerance is NEGATIVE_TOL_FRACTION times that scale.
NEGATIVE_TOL_FRACTION = 1e-2


def scaled_negative_tol(scene):
    """DEFAULT_NEGATIVE_TOL, or NEGATIVE_TOL_FRACTION (2 pi l / L)^4 where that is smaller (long
    rods, whose softest modes go like N^-4 in the scaled units)."""
    import math

    ratio = 2.0 * math.pi * float(scene.length_scale) / float(scene.length)
    return min(DEFAULT_NEGATIVE_TOL, NEGATIVE_TOL_FRACTION * ratio**4)
