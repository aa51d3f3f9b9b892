"""Cosserat rods with shear and extension (Simo–Reissner): a scene kind of its own.

The Kirchhoff scenes (``jaxrod.model.rods``) hold the centreline inextensible in shear: their frame
follows the tangent. Here each edge carries a rotation of its own, so the cross-section can shear
against the centreline, as in Simo–Reissner rods and PyElastica. Only the scenes that need shear
pay for it: 6 DOFs per node instead of 4.

Degrees of freedom: node positions x (N + 1, 3) and one rotation per edge, a rotation vector psi
(N, 3), R = exp(psi^) through the unit quaternion q(psi) (smooth at psi = 0: a series there).
Strains, per edge j (length l_j) and per joint k between edges k - 1 and k (length (l_{k-1} + l_k) / 2):

    Gamma_j = R_j^T (x_{j+1} - x_j) / l_j - e3      shear (1, 2) and extension (3), in the material frame
    kappa_k = 2 vec(conj(q_{k-1}) q_k) / lbar_k       bending (1, 2) and twist (3)

    E = sum_j l_j / 2 Gamma_j^T diag(kGA, kGA, EA) Gamma_j + sum_k lbar_k / 2 kappa_k^T diag(B, B, C) kappa_k
        - (work of the load)

kappa is 2 sin(theta / 2) / lbar times the axis of the relative rotation: the curvature to third
order in theta, smooth where the log map is not. Supports (``support``):

- ``"cantilever"``: node 0 at the origin and a clamp frame R = I before edge 0 (a joint of length
  l_0 / 2); the load is a dead force ``load`` e1 at node N (shear and bending).
- ``"pinned"``: node 0 at the origin, node N on the z axis (free along it), frames free, the twist of
  edge 0 held (the rod's rotation about its axis is a zero mode); the load is a compressive dead
  force ``load`` along -e3 at node N (a column).

The shear strain measured in the material frame makes the column's buckling load Haringx's, not
Engesser's (docs/guides/shear.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..validation import check_int_at_least, check_positive

__all__ = ["CosseratRod", "cosserat_rod", "CosseratRing", "cosserat_ring", "SUPPORTS"]

SUPPORTS = ("cantilever", "pinned")
_SERIES = 1e-6  # below this psi . psi the quaternion's series is exact to roundoff


def _quaternion(psi):
    """Unit quaternions (w, v) (..., 4) of rotation vectors psi (..., 3), smooth at psi = 0."""
    a = jnp.sum(psi * psi, axis=-1)
    small = a < _SERIES
    safe = jnp.where(small, 1.0, a)
    angle = jnp.sqrt(safe)
    w = jnp.where(small, 1.0 - a / 8.0, jnp.cos(0.5 * angle))
    s = jnp.where(small, 0.5 - a / 48.0, jnp.sin(0.5 * angle) / angle)  # sin(|psi|/2) / |psi|
    return jnp.concatenate([w[..., None], s[..., None] * psi], axis=-1)


def _rotation(q):
    """R (..., 3, 3) of unit quaternions q (..., 4)."""
    w, v = q[..., 0], q[..., 1:]
    eye = jnp.eye(3)
    cross = jnp.stack([jnp.stack([0.0 * w, -v[..., 2], v[..., 1]], -1),
                       jnp.stack([v[..., 2], 0.0 * w, -v[..., 0]], -1),
                       jnp.stack([-v[..., 1], v[..., 0], 0.0 * w], -1)], -2)
    return ((w * w - jnp.sum(v * v, -1))[..., None, None] * eye + 2.0 * v[..., :, None] * v[..., None, :]
            + 2.0 * w[..., None, None] * cross)


def _product(a, b):
    """Quaternion products a b (..., 4)."""
    wa, va, wb, vb = a[..., :1], a[..., 1:], b[..., :1], b[..., 1:]
    return jnp.concatenate([wa * wb - jnp.sum(va * vb, -1, keepdims=True), wa * vb + wb * va + jnp.cross(va, vb)], -1)


def _from_matrix(R):
    """Unit quaternions (N, 4) of rotation matrices R (N, 3, 3) whose trace is > -1 (numpy)."""
    w = 0.5 * np.sqrt(1.0 + np.trace(R, axis1=1, axis2=2))
    v = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], -1) / (4.0 * w[:, None])
    return np.concatenate([w[:, None], v], -1)


def _elastic(gamma, kappa, l, params):
    """sum l / 2 (Gamma^T diag(kGA, kGA, EA) Gamma + kappa^T diag(B, B, C) kappa) over edges and joints."""
    B, C, EA, GA = params[0], params[1], params[2], params[3]
    shear = jnp.sum(GA * (gamma[:, 0] ** 2 + gamma[:, 1] ** 2) + EA * gamma[:, 2] ** 2)
    return 0.5 * l * (shear + jnp.sum(jnp.stack([B, B, C]) * kappa ** 2))


def _relative_vector(q1, q2):
    """vec(conj(q1) q2) (..., 3): sin(theta / 2) times the axis of R1^T R2, in the frame of R1."""
    w1, v1, w2, v2 = q1[..., :1], q1[..., 1:], q2[..., :1], q2[..., 1:]
    return w1 * v2 - w2 * v1 - jnp.cross(v1, v2)


@dataclass(frozen=True, eq=False)
class _CosseratStiffness:
    """N edges of total rest length ``length``; bending B, twist C, extension EA and shear kGA."""

    N: int
    length: float
    B: float
    C: float
    EA: float
    GA: float

    @property
    def params(self):
        """(B, C, EA, GA) (4,), the ``params`` argument of the energy."""
        return jnp.array([self.B, self.C, self.EA, self.GA], dtype=jnp.float64)


def _checked_stiffness(N, minimum, length, B, C, EA, GA):
    """(int N, floats): ValueError naming the argument for N < minimum or a value that is not > 0."""
    check_int_at_least("N", N, minimum)
    for name, value in (("length", length), ("B", B), ("C", C), ("EA", EA), ("GA", GA)):
        check_positive(name, value)
    return int(N), float(length), float(B), float(C), float(EA), float(GA)


@dataclass(frozen=True)
class CosseratRod(_CosseratStiffness):
    """A straight Cosserat rod of N edges along e3 (length ``length``), with bending B, twist C,
    extension EA and shear kGA stiffnesses, and a ``support`` in ``SUPPORTS``.

    The energy ``energy(u, load, params)`` is a pure JAX function of the free DOFs u (``n_free``,)
    (``full`` embeds them), the load (a scalar: the tip force, see the module docstring) and
    ``params`` = (B, C, EA, GA) (``params``: the rod's own), so that ``jax.grad`` and ``jax.hessian``
    differentiate it in every argument."""

    support: str = "cantilever"

    @property
    def n_full(self):
        return 3 * (self.N + 1) + 3 * self.N

    @property
    def free(self):
        """Indices (n_free,) of the free DOFs in the full vector [x (N + 1, 3) raveled, psi (N, 3) raveled]."""
        held = [0, 1, 2]  # node 0 at the origin
        if self.support == "pinned":
            held += [3 * self.N, 3 * self.N + 1, 3 * (self.N + 1) + 2]  # node N on the axis; edge 0's twist
        return np.setdiff1d(np.arange(self.n_full), held)

    def full(self, u):
        """(x (N + 1, 3), psi (N, 3)) of the free DOFs u (n_free,); held DOFs are 0."""
        z = jnp.zeros(self.n_full, dtype=jnp.asarray(u).dtype).at[jnp.asarray(self.free)].set(u)
        return z[:3 * (self.N + 1)].reshape(self.N + 1, 3), z[3 * (self.N + 1):].reshape(self.N, 3)

    def straight(self, load=0.0):
        """The free DOFs (n_free,) of the straight, untwisted state, stretched by the axial force
        (the pinned column's -load: z_j = s_j (1 - load / EA)); an equilibrium for the column."""
        axial = -float(load) / self.EA if self.support == "pinned" else 0.0
        s = np.linspace(0.0, self.length, self.N + 1)
        x = np.stack([0.0 * s, 0.0 * s, s * (1.0 + axial)], axis=1)
        return np.concatenate([x.ravel(), np.zeros(3 * self.N)])[self.free]

    def energy(self, u, load, params):
        """E (scalar) at free DOFs u (n_free,) under ``load``, with params = (B, C, EA, GA)."""
        x, psi = self.full(u)
        l = self.length / self.N
        q = _quaternion(psi)
        gamma = jnp.einsum("jab,ja->jb", _rotation(q), (x[1:] - x[:-1]) / l) - jnp.array([0.0, 0.0, 1.0])
        kappa = 2.0 * _relative_vector(q[:-1], q[1:]) / l
        energy = _elastic(gamma, kappa, l, params)
        if self.support == "cantilever":  # the clamp frame R = I before edge 0: a joint of length l / 2
            kappa0 = 2.0 * q[0, 1:] / (0.5 * l)
            bend0 = 0.25 * l * jnp.sum(jnp.stack([params[0], params[0], params[1]]) * kappa0 ** 2)
            return energy + bend0 - load * x[-1, 0]
        return energy + load * x[-1, 2]


def cosserat_rod(*, N, length, B, C, EA, GA, support="cantilever"):
    """A straight ``CosseratRod`` of N edges (N >= 2) and the given stiffnesses (all > 0); ValueError
    naming the argument otherwise."""
    values = _checked_stiffness(N, 2, length, B, C, EA, GA)
    if support not in SUPPORTS:
        raise ValueError(f"support must be one of {', '.join(SUPPORTS)}, got {support!r}")
    return CosseratRod(*values, support)


@dataclass(frozen=True, eq=False)
class CosseratRing(_CosseratStiffness):
    """A closed Cosserat rod (a ring) of N edges of length ``length`` / N, naturally straight,
    twisted by phi at its closure: the frame that edge 0 comes back with is R_0 exp(phi e3).

    DOFs: node positions x (N, 3) and rotation vectors psi (N, 3) relative to reference frames
    q_ref_j q(j phi / N e3) (the regular polygon's frames, d3 along the edge, d2 = e_z, with the
    twist spread evenly), so that the planar twisted ring is near psi = 0 at every phi. Seven DOFs
    are held at the polygon's values (node 0's position, x and z of node N/4, z of node N/2: the
    rigid motions; edge 0's psi_3: the uniform rotation of every frame about its own d3, an exact
    symmetry for an isotropic section). ``energy(u, phi, params)`` is a pure JAX function."""

    def _polygon(self):
        l = self.length / self.N
        radius = l / (2.0 * np.sin(np.pi / self.N))
        angle = 2.0 * np.pi * np.arange(self.N) / self.N
        x = radius * np.stack([np.cos(angle), np.sin(angle), 0.0 * angle], -1)
        d3 = np.roll(x, -1, axis=0) - x
        d3 /= np.linalg.norm(d3, axis=1, keepdims=True)
        d2 = np.broadcast_to(np.array([0.0, 0.0, 1.0]), d3.shape)
        frames = np.stack([np.cross(d2, d3), d2, d3], axis=-1)  # columns d1, d2, d3
        return x, _from_matrix(frames)

    @property
    def free(self):
        N = self.N
        held = [0, 1, 2, 3 * (N // 4), 3 * (N // 4) + 2, 3 * (N // 2) + 2, 3 * N + 2]
        return np.setdiff1d(np.arange(6 * N), held)

    def circle(self):
        """The free DOFs (n_free,) of the planar polygon with frames on the reference (psi = 0)."""
        x, _ = self._polygon()
        return np.concatenate([x.ravel(), np.zeros(3 * self.N)])[self.free]

    def full(self, u):
        """(x (N, 3), psi (N, 3)) of the free DOFs u (n_free,), the held ones at the polygon's values."""
        x, _ = self._polygon()
        ref = jnp.asarray(np.concatenate([x.ravel(), np.zeros(3 * self.N)]))
        z = ref.at[jnp.asarray(self.free)].set(u)
        return z[:3 * self.N].reshape(self.N, 3), z[3 * self.N:].reshape(self.N, 3)

    def energy(self, u, phi, params):
        """E (scalar) at free DOFs u (n_free,) and closure twist phi (rad), params = (B, C, EA, GA)."""
        x, psi = self.full(u)
        _, q_ref = self._polygon()
        l = self.length / self.N
        e3 = jnp.array([0.0, 0.0, 1.0])
        spread = _quaternion((phi * jnp.arange(self.N) / self.N)[:, None] * e3)
        q = _product(_product(jnp.asarray(q_ref), spread), _quaternion(psi))
        gamma = jnp.einsum("jab,ja->jb", _rotation(q), (jnp.roll(x, -1, axis=0) - x) / l) - e3
        back = _product(q[:1], _quaternion(phi * e3)[None])  # edge 0's frame after one turn
        kappa = 2.0 * _relative_vector(q, jnp.concatenate([q[1:], back])) / l
        return _elastic(gamma, kappa, l, params)


def cosserat_ring(*, N, length, B, C, EA, GA):
    """A ``CosseratRing`` of N edges (N >= 8, a multiple of 4) and the given stiffnesses (all > 0)."""
    values = _checked_stiffness(N, 8, length, B, C, EA, GA)
    if values[0] % 4:
        raise ValueError(f"N must be a multiple of 4 (its gauge pins sit at nodes N/4 and N/2), got {N}")
    return CosseratRing(*values)
