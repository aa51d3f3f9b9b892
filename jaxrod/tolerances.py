"""Eigenvalue tolerances shared by the stability analyses (dense and O(N)): in the lowest layer, so
that ``stability``, ``sparse_stability`` and ``sparse_contact`` all import them from below."""

# An eigenvalue counts as negative below -DEFAULT_NEGATIVE_TOL (dimensionless units). Well below
# the softest physical mode of the rods studied (>1e-7 for N <= 512 rings), above round-off.
DEFAULT_NEGATIVE_TOL = 1e-10
# Near-zero modes of a loose knot (strands sliding along each other) sit at |lambda| ~ 1e-7 in the
# scaled units and change sign from step to step: with self-contact an eigenvalue counts as
# negative, and enters the branch tangent, only beyond this.
CONTACT_NEGATIVE_TOL = 1e-6
