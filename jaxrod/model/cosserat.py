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

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..validation import check_int_at_least, check_positive

__all__ = ["CosseratRod", "cosserat_rod", "CosseratRing", "cosserat_ring", "CosseratKnot", "cosserat_knot", "SUPPORTS"]

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
    """Unit quaternions (N, 4) of rotation matrices R (N, 3, 3) (numpy; Shepperd's method: each
    from its largest component, so that no rotation angle divides by a small number)."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R, axis1=1, axis2=2)
    squares = np.stack([1.0 + tr, 1.0 + 2.0 * R[:, 0, 0] - tr, 1.0 + 2.0 * R[:, 1, 1] - tr,
                        1.0 + 2.0 * R[:, 2, 2] - tr], -1)  # 4 w^2, 4 x^2, 4 y^2, 4 z^2
    big = np.argmax(squares, axis=1)
    q = np.empty((R.shape[0], 4))
    for n, i in enumerate(big):
        r, c = R[n], 0.5 * np.sqrt(squares[n, i])
        skew = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
        sym = {1: (r[0, 1] + r[1, 0], r[0, 2] + r[2, 0]), 2: (r[0, 1] + r[1, 0], r[1, 2] + r[2, 1]),
               3: (r[0, 2] + r[2, 0], r[1, 2] + r[2, 1])}
        if i == 0:
            q[n] = [c, *(skew / (4.0 * c))]
        else:
            others = iter(sym[i])
            v = [next(others) / (4.0 * c) if j != i else c for j in (1, 2, 3)]
            q[n] = [skew[i - 1] / (4.0 * c), *v]
    return q * np.where(q[:, :1] < 0.0, -1.0, 1.0)


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


def _edge_energy(xa, xb, psi, left, l, params):
    """Shear and extension of one edge from node xa to xb (3,), its frame left q(psi) (left (4,)):
    l / 2 Gamma^T diag(kGA, kGA, EA) Gamma, Gamma = R^T (xb - xa) / l - e3."""
    gamma = _rotation(_product(left, _quaternion(psi))).T @ ((xb - xa) / l) - jnp.array([0.0, 0.0, 1.0])
    return 0.5 * l * (params[3] * (gamma[0] ** 2 + gamma[1] ** 2) + params[2] * gamma[2] ** 2)


def _joint_energy(psi_a, psi_b, left_a, left_b, right_b, l, params):
    """Bending and twist of one joint between the frames left_a q(psi_a) and left_b q(psi_b) right_b:
    l / 2 kappa^T diag(B, B, C) kappa, kappa = 2 vec(conj(q_a) q_b) / l."""
    qa = _product(left_a, _quaternion(psi_a))
    qb = _product(_product(left_b, _quaternion(psi_b)), right_b)
    kappa = 2.0 * _relative_vector(qa, qb) / l
    return 0.5 * l * (params[0] * (kappa[0] ** 2 + kappa[1] ** 2) + params[1] * kappa[2] ** 2)


@dataclass(frozen=True, eq=False)
class CosseratKnot(_CosseratStiffness):
    """A closed Cosserat rod tied in a knot, with soft self-contact, twisted by phi at its closure
    (the frame that edge 0 comes back with is R_0 exp(phi e3), as in ``CosseratRing``).

    Built by ``cosserat_knot`` from a Kirchhoff knot's equilibrium at phi = 0: ``x_ref`` (N, 3)
    its nodes and ``q_ref`` (N, 4) its material frames (d3 along each edge, so no shear there). The
    DOFs are the node positions and rotation vectors psi (N, 3) relative to q_ref_j q(j phi / N e3)
    (the twist spread evenly, so that psi stays small at any phi). Seven DOFs are held at their
    reference values, a gauge for the seven exact symmetries: node 0's position, two coordinates
    of a second node and one of a third (chosen where the rigid rotations move them most), and edge
    0's psi_3 (every frame turned about its own d3). Contact: ``contact_energy`` over the segment
    pairs ``pairs`` (every pair further apart along the rod than pi D / 2), with the diameter D and
    ``contact_stiffness`` (units of B / D^3) of the Kirchhoff scene. ``energy(u, phi, params)`` is a
    pure JAX function."""

    D: float
    contact_stiffness: float
    x_ref: np.ndarray
    q_ref: np.ndarray
    held: tuple
    pairs: np.ndarray

    @property
    def free(self):
        return np.setdiff1d(np.arange(6 * self.N), np.asarray(self.held))

    @functools.cached_property
    def continuation_functions(self):
        """(energy(u, phi, args), hessian(u, phi, args)) with args = (params, pairs (P, 2), mask (P,)):
        the forms the continuation engine takes, built once per knot, so that its compiled programs
        serve every params (a sweep in GA compiles them once)."""
        def energy(u, phi, args):
            return self.energy(u, phi, args[0], (args[1], args[2]))

        def hessian(u, phi, args):
            return self.hessian(u, phi, args[0], (args[1], args[2]))

        return energy, hessian

    def start(self):
        """The free DOFs (n_free,) of the reference state (the Kirchhoff equilibrium, psi = 0)."""
        return np.concatenate([self.x_ref.ravel(), np.zeros(3 * self.N)])[self.free]

    def full(self, u):
        """(x (N, 3), psi (N, 3)) of the free DOFs u (n_free,), the held ones at their reference values."""
        ref = jnp.asarray(np.concatenate([self.x_ref.ravel(), np.zeros(3 * self.N)]))
        z = ref.at[jnp.asarray(self.free)].set(u)
        return z[:3 * self.N].reshape(self.N, 3), z[3 * self.N:].reshape(self.N, 3)

    def _stencils(self, u, phi):
        """(x (N, 3), psi (N, 3), left (N, 4), right (N, 4)): the positions and rotation vectors, and
        each edge's frame as left_j q(psi_j), with left_j = q_ref_j q(j phi / N e3); right: the
        rotation after q(psi) of each joint's second edge (identity, and q(phi e3) at the closure,
        where edge 0 comes back turned by phi)."""
        x, psi = self.full(u)
        e3 = jnp.array([0.0, 0.0, 1.0])
        left = _product(jnp.asarray(self.q_ref), _quaternion((phi * jnp.arange(self.N) / self.N)[:, None] * e3))
        identity = jnp.zeros((self.N - 1, 4)).at[:, 0].set(1.0)
        right = jnp.concatenate([identity, _quaternion(phi * e3)[None]])
        return x, psi, left, right

    def energy(self, u, phi, params, contact=None):
        """E (scalar) at free DOFs u (n_free,) and closure twist phi (rad), params = (B, C, EA, GA);
        contact: (pairs (P, 2), mask (P,)), a candidate list (``contact_list``) that holds every
        pair within D at u, or None for every pair (``pairs``)."""
        from .contact import contact_energy

        x, psi, left, right = self._stencils(u, phi)
        l = self.length / self.N
        nxt = np.roll(np.arange(self.N), -1)
        edges = jax.vmap(_edge_energy, (0, 0, 0, 0, None, None))(x, x[nxt], psi, left, l, params)
        joints = jax.vmap(_joint_energy, (0, 0, 0, 0, 0, None, None))(psi, psi[nxt], left, left[nxt], right, l, params)
        pairs, mask = (self.pairs, np.ones(len(self.pairs), dtype=bool)) if contact is None else contact
        return jnp.sum(edges) + jnp.sum(joints) + contact_energy(x, pairs, mask, True, self.D, params[0],
                                                                 self.contact_stiffness)

    def hessian(self, u, phi, params, contact=None):
        """The Hessian (n_free, n_free) of ``energy`` in u, assembled from its local blocks: 9 x 9 per
        edge (its two nodes and its rotation), 6 x 6 per joint (two rotations), and the contact's
        closed-form 12 x 12 per pair (``contact_pair_hessian``): N + N + P small Hessians against the
        n_free reverse passes of ``jax.hessian``."""
        from .contact import contact_pair_hessian

        x, psi, left, right = self._stencils(u, phi)
        N, l = self.N, self.length / self.N
        nxt = np.roll(np.arange(N), -1)
        node = lambda j: 3 * np.asarray(j)[:, None] + np.arange(3)  # noqa: E731
        turn = lambda j: 3 * N + node(j)  # noqa: E731
        edge = jax.vmap(jax.hessian(lambda y, lft: _edge_energy(y[:3], y[3:6], y[6:], lft, l, params)))
        joint = jax.vmap(jax.hessian(lambda y, la, lb, r: _joint_energy(y[:3], y[3:], la, lb, r, l, params)))
        j = np.arange(N)
        blocks = [(edge(jnp.concatenate([x, x[nxt], psi], 1), left),
                   np.concatenate([node(j), node(nxt), turn(j)], 1)),
                  (joint(jnp.concatenate([psi, psi[nxt]], 1), left, left[nxt], right),
                   np.concatenate([turn(j), turn(nxt)], 1))]
        pairs, mask = (self.pairs, np.ones(len(self.pairs), dtype=bool)) if contact is None else contact
        pairs = jnp.asarray(pairs)
        a, b = pairs[:, 0], pairs[:, 1]
        segments = jnp.concatenate([x[a], x[(a + 1) % N], x[b], x[(b + 1) % N]], 1)
        contact_blocks = contact_pair_hessian(segments, self.D, params[0], self.contact_stiffness)
        contact_index = jnp.concatenate([3 * a[:, None] + jnp.arange(3), 3 * ((a + 1) % N)[:, None] + jnp.arange(3),
                                         3 * b[:, None] + jnp.arange(3), 3 * ((b + 1) % N)[:, None] + jnp.arange(3)], 1)
        blocks.append((jnp.where(jnp.asarray(mask)[:, None, None], contact_blocks, 0.0), contact_index))
        H = jnp.zeros((6 * N, 6 * N))
        for values, index in blocks:
            index = jnp.asarray(index)
            H = H.at[index[:, :, None], index[:, None, :]].add(values)
        free = jnp.asarray(self.free)
        return H[free[:, None], free[None, :]]

    def contact_list(self, u, capacity=None):
        """The candidate segment pairs at free DOFs u (a ``ContactList``: a k-d tree with a skin of
        D / 2, valid while no node moves more than D / 4), padded to ``capacity`` (default four times
        the pairs found, at least 4 N)."""
        from .contact import candidate_pairs

        x = np.asarray(self.full(jnp.asarray(u))[0])
        found = candidate_pairs(x, True, self.length / self.N, self.D, capacity=len(self.pairs))
        cap = max(4 * found.n_candidates, 4 * self.N) if capacity is None else capacity
        return candidate_pairs(x, True, self.length / self.N, self.D, capacity=min(cap, len(self.pairs)))


def _knot_gauge(x):
    """Seven held DOFs of a closed rod's nodes x (N, 3): node 0's position; two coordinates of the
    node that rigid rotations about node 0 move most, then one coordinate of the node that the
    rotation left free moves most; edge 0's psi_3."""
    N = x.shape[0]
    r = x - x[0]
    a = int(np.argmax(np.linalg.norm(r, axis=1)))
    rot = lambda w, y: np.cross(w, y)  # noqa: E731
    moves_a = np.stack([rot(w, r[a]) for w in np.eye(3)], axis=1)  # (coordinate, rotation axis)
    pairs = [(i, j) for i in range(3) for j in range(i + 1, 3)]
    pick = max(pairs, key=lambda ij: np.linalg.svd(moves_a[list(ij)], compute_uv=False)[1])
    left = np.linalg.svd(moves_a[list(pick)])[2][-1]  # the rotation the two pins leave free
    moves = np.abs(np.cross(left, r))
    b, c = np.unravel_index(int(np.argmax(moves)), moves.shape)
    return (0, 1, 2, 3 * a + pick[0], 3 * a + pick[1], 3 * int(b) + int(c), 3 * N + 2)


def cosserat_knot(scene, state, *, GA=None, shear_coefficient=None):
    """The ``CosseratKnot`` of a Kirchhoff knot ``scene`` (a closed rod with contact, from
    ``jaxrod.trefoil`` or ``jaxrod.knot``) and its equilibrium ``state`` at phi = 0, with the scene's
    B, C, EA, D and contact stiffness.

    GA: the shear stiffness kGA; default k G A of a solid circular section, G A = 8 C / D^2 (from
    C = G pi D^4 / 32) and Cowper's k = 6 (1 + nu) / (7 + 6 nu), nu = B / C - 1
    (``shear_coefficient`` replaces k)."""
    from .contact import all_pairs

    m = scene.material
    if not scene.closed or not scene.has_term("contact") or m.D is None:
        raise ValueError("scene must be a closed rod with contact (a knot from jaxrod.trefoil or jaxrod.knot)")
    B, C, EA, D = float(m.B), float(m.C), float(m.EA), float(m.D)
    nu = B / C - 1.0
    k = 6.0 * (1.0 + nu) / (7.0 + 6.0 * nu) if shear_coefficient is None else float(shear_coefficient)
    GA = k * 8.0 * C / D ** 2 if GA is None else GA
    x = np.asarray(scene.positions(state.q), dtype=float)
    d1, d2, d3 = (np.asarray(d, dtype=float) for d in scene.material_frames(state.q, 0.0))
    N, length = x.shape[0], float(scene.length)
    values = _checked_stiffness(N, 8, length, B, C, EA, GA)
    return CosseratKnot(*values, D=D, contact_stiffness=float(scene.contact_stiffness), x_ref=x,
                        q_ref=_from_matrix(np.stack([d1, d2, d3], axis=-1)), held=_knot_gauge(x),
                        pairs=all_pairs(N, True, length / N, D))
