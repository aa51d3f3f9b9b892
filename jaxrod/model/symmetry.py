"""The two-fold symmetry of a closed rod about an axis through its joint, and the projection onto it.

A closed rod whose joint (vertex 0) lies on a two-fold axis of its centreline (the drawn trefoil
does) is mapped onto itself by the rotation R by pi about it, which sends node i to node -i (mod N)
and edge j to edge N-1-j. With uniform rest lengths the discrete energy is invariant under it:

    x'_i = R x_{-i} + t,        theta'_j = -theta_{N-1-j} + 2 mean(theta)

(the joint keeps its holonomy: the writhe is unchanged by a rotation and by reversing direction).

Why a continuation needs it: a loose knot's sliding modes are nearly null, so a minimiser stopped
at its gradient tolerance leaves the material anywhere along a slide and a path drifts between
symmetric placements of the nodes. A slide is odd under the symmetry, so the projection onto the
symmetric states removes it. Every instability is still seen: stability is judged on the full
Hessian, so a symmetry-breaking mode going negative ends the branch (a branch point).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .scenes import ClosedRod

__all__ = ["TwoFold", "has_joint_symmetry", "joint_two_fold", "two_fold_asymmetry", "symmetrize", "symmetrize_pinned",
           "SYMMETRIC_TOL", "ROUND_OFF_ASYMMETRY"]

# A state is on a two-fold symmetry (``ContinuationOptions.keep_symmetry``) when its nodes' rms
# distance from their images is below SYMMETRIC_TOL edge lengths (a drawn trefoil has ~1e-14). Each
# corrected state further from it than ROUND_OFF_ASYMMETRY edges is projected back, so the next one
# starts symmetric.
SYMMETRIC_TOL = 1e-5
ROUND_OFF_ASYMMETRY = 1e-12


@dataclass(frozen=True)
class TwoFold:
    """The rotation by pi about ``axis`` (unit, (3,)) through ``centre`` ((3,)) that maps node i to
    node -i; ``asymmetry``: the rms distance (length units) of x_i from the image of x_{-i}."""

    axis: np.ndarray
    centre: np.ndarray
    asymmetry: float

    @property
    def rotation(self):
        a = self.axis
        return 2.0 * np.outer(a, a) - np.eye(3)

    def map_positions(self, x):
        """x (N, 3) -> the mapped positions R x_{-i} + t."""
        mirrored = x[(-np.arange(x.shape[0])) % x.shape[0]]
        return (mirrored - self.centre) @ self.rotation.T + self.centre


def has_joint_symmetry(scene):
    """Whether the scene's energy is invariant under the map: a closed rod with uniform rest lengths
    (the vertices' Voronoi lengths then are too)."""
    if not isinstance(scene, ClosedRod):  # its DOF layout, holonomy at vertex 0
        return False
    rest = np.asarray(scene.rest_lengths, dtype=float)
    return bool(np.all(np.abs(rest - rest.mean()) <= 1e-12 * rest.mean()))


def two_fold_asymmetry(x):
    """The best two-fold map of the closed polyline x (N, 3) onto itself with node i -> node -i:
    a ``TwoFold`` whose axis comes from the best-fit rotation (Kabsch) of the mirrored nodes onto
    x, made an exact rotation by pi. Its ``asymmetry`` is the rms distance that map leaves."""
    x = np.asarray(x, dtype=float)
    mirrored = x[(-np.arange(x.shape[0])) % x.shape[0]]
    c = x.mean(axis=0)  # the index map is a permutation: the centroid lies on the axis
    a0, b0 = mirrored - c, x - c
    u, _, vt = np.linalg.svd(a0.T @ b0)
    d = np.sign(np.linalg.det(u @ vt))
    r = (u @ np.diag([1.0, 1.0, d]) @ vt).T  # the rotation taking mirrored onto x
    # A rotation by pi is 2 a a^T - I: its axis is the symmetric part's eigenvector of eigenvalue 1.
    w, v = np.linalg.eigh(0.5 * (r + r.T))
    axis = v[:, -1]
    sym = TwoFold(axis=axis, centre=c, asymmetry=0.0)
    rms = float(np.sqrt(np.mean(np.sum((x - sym.map_positions(x)) ** 2, axis=1))))
    return TwoFold(axis=axis, centre=c, asymmetry=rms)


def joint_two_fold(scene, q, tol):
    """The ``TwoFold`` of the state q if the scene's energy has the symmetry and q has it to within
    ``tol`` (rms, length units); else None."""
    if not has_joint_symmetry(scene):
        return None
    sym = two_fold_asymmetry(np.asarray(scene.positions(np.asarray(q, dtype=float))))
    return sym if sym.asymmetry <= tol else None


def symmetrize(scene, q, sym=None):
    """q projected onto the states with the two-fold symmetry ``sym`` (default: the best fit to q):
    the mean of q and its image, so a symmetric q is returned unchanged (to round-off) and the
    result's image is itself. q: (3N + N,) physical DOFs of a ``ClosedRod``."""
    q = np.asarray(q, dtype=float)
    n = scene.n_nodes
    x, theta = q[:3 * n].reshape(n, 3), q[3 * n:]
    if sym is None:
        sym = two_fold_asymmetry(x)
    x_sym = 0.5 * (x + sym.map_positions(x))
    theta_image = -theta[::-1] + 2.0 * theta.mean()
    theta_sym = 0.5 * (theta + theta_image)
    return np.concatenate([x_sym.ravel(), theta_sym])


def _rotation(omega):
    """The rotation matrix of the rotation vector omega (3,) (Rodrigues)."""
    angle = float(np.linalg.norm(omega))
    if angle == 0.0:
        return np.eye(3)
    k = np.asarray(omega, dtype=float) / angle
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def symmetrize_pinned(scene, q, pins, values, sym=None, iterations=4):
    """``symmetrize`` for a gauge-pinned problem (``jaxrod.continuation.arclength.rods``): q (4N,)
    projected onto the symmetric states, then moved by the rigid motion and uniform twist shift
    (7 parameters, which keep the symmetry) that puts the scaled DOFs at ``pins`` (7,) back at
    ``values`` (7,), by Newton on those 7 equations. Returns q (4N,)."""
    n = scene.n_nodes
    q_sym = symmetrize(scene, q, sym)
    x, theta = q_sym[:3 * n].reshape(n, 3), q_sym[3 * n:]
    centre = x.mean(axis=0)
    pins = np.asarray(pins)
    values = np.asarray(values, dtype=float)

    def moved(z):
        x_new = (x - centre) @ _rotation(z[:3]).T + centre + z[3:6]
        return np.concatenate([x_new.ravel(), theta + z[6]])

    def residual(z):
        return np.asarray(scene.to_scaled(moved(z)))[pins] - values

    z = np.zeros(7)
    r = residual(z)
    for _ in range(iterations):
        if not np.max(np.abs(r)) > 1e-15 * max(1.0, float(np.max(np.abs(values)))):
            break
        h = 1e-7
        jac = np.stack([(residual(z + h * e) - residual(z - h * e)) / (2 * h) for e in np.eye(7)], axis=1)
        z = z - np.linalg.solve(jac, r)
        r = residual(z)
    return moved(z)
