"""Rods clamped at both ends along one axis, the far clamp displaced (displacement control).

See ``jaxrod.studies.endloads`` for the setting: the far clamp sits L - shortening from the near
one along the axis, its edge on the axis and its frame turned by ``phi``.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from ...model.material import Material
from ...model.scenes import ClampedRod, _pytree, clamped_rod
from ...validation import check_finite, check_positive


@_pytree(["material", "rest_lengths", "q_init", "x_clamped", "director_start", "Lk0", "end_offset",
          "contact_stiffness"], ["terms", "name", "contact_quadrature"])
@dataclass(frozen=True, eq=False)
class EndLoadedRod(ClampedRod):
    """A ``ClampedRod`` whose far clamp (nodes N-2, N-1) is displaced by ``end_offset`` (3,) from
    its place one rod length from the near clamp; its edge keeps the axis direction. A shortening
    s is ``end_offset = -s * axis``. DOFs as ``ClampedRod``: q = [x[2:N-2].ravel(), theta[1:M-1]].
    ``contact_stiffness``: kappa_c of soft self-contact when "contact" is a term (as ``ClosedRod``);
    ``contact_quadrature``: Gauss points per segment in the contact integral (static: 1, 2 or 3)."""

    end_offset: np.ndarray = None
    contact_stiffness: float = 0.0
    contact_quadrature: int = 2

    # One exact zero mode: rotating the interior nodes rigidly about the clamp axis leaves the
    # energy unchanged (both clamped edges lie on the axis).
    n_zero_modes = 1

    def zero_modes(self, q, phi):
        """(n, 1): the rigid rotation of the interior nodes about the clamp axis."""
        xi, theta = self.interior(q)
        rot = jnp.cross(self.axis[None, :], xi - self.x_clamped[0][None, :]).ravel()
        return jnp.concatenate([rot, jnp.zeros_like(theta)])[:, None]

    def nodes(self, q):
        xi, _ = self.interior(q)
        c = self.x_clamped
        return jnp.concatenate([c[:2], xi, c[2:] + self.end_offset[None, :]], axis=0)

    @property
    def shortening(self):
        """Distance the far clamp has moved towards the near one along the axis."""
        return -jnp.dot(self.end_offset, self.axis)

    @property
    def clamp_length(self):
        """L: the rest length between the clamps' material points (the midpoints of the clamped
        end edges), (N - 2) edges; ``length`` counts all N - 1 edges."""
        return jnp.sum(self.voronoi)

    @property
    def end_distance(self):
        """Distance between the clamp points along the axis (L when the shortening is 0)."""
        return self.clamp_length - self.shortening


def with_end_offset(scene, offset):
    """``scene`` with its far clamp displaced by ``offset`` (3,) from the unshortened position.
    Traceable (offset may be a tracer): a shallow copy, no validation."""
    new = copy.copy(scene)
    object.__setattr__(new, "end_offset", jnp.asarray(offset, dtype=jnp.float64))
    return new


def with_shortening(scene, shortening):
    """``scene`` with the far clamp ``shortening`` closer to the near one along the axis. Traceable."""
    return with_end_offset(scene, -shortening * scene.axis)


def shortened_rod(N, length, material, shortening=0.0, axis=(0.0, 0.0, 1.0), contact_stiffness=None, Lk0=0.0,
                  contact_quadrature=2):
    """A rod of rest length ``length`` (between the clamps' material points, as ``clamped_rod``)
    with N nodes, clamped at both ends along ``axis``, the far clamp ``shortening`` closer than one
    rod length (0 <= shortening < length). q_init: straight, uniformly compressed, no twist.
    contact_stiffness: kappa_c of soft self-contact (needs the material's D); None: no contact.
    contact_quadrature: Gauss points per segment of the contact integral (1, 2 or 3; 3 for a knot
    pulled tight)."""
    if contact_quadrature not in (1, 2, 3):
        raise ValueError(f"contact_quadrature must be 1, 2 or 3 Gauss points per segment, got {contact_quadrature!r}")
    base = clamped_rod(N=N, length=length, material=material, axis=axis)
    length = float(length)
    s = check_finite("shortening", shortening)
    if not 0.0 <= s < length:
        raise ValueError(f"shortening must lie in [0, length) = [0, {length:g}), got {shortening!r}")
    kc = 0.0
    if contact_stiffness is not None:
        if material.D is None:
            raise ValueError("contact needs the rod diameter: give the material a D")
        kc = check_positive("contact_stiffness", contact_stiffness)
    a = np.asarray(base.axis)
    xc = np.asarray(base.x_clamped)
    n_free = N - 4
    q0 = np.asarray(base.q_init).copy()
    # evenly spaced between the near clamp's node 1 and the far clamp's node N-2
    start, stop = xc[1], xc[2] - s * a
    frac = np.arange(1, n_free + 1) / (n_free + 1)
    q0[:3 * n_free] = (start[None, :] + frac[:, None] * (stop - start)[None, :]).ravel()
    rod = EndLoadedRod(material=material, rest_lengths=base.rest_lengths, q_init=jnp.asarray(q0),
                       x_clamped=base.x_clamped, director_start=base.director_start, Lk0=float(Lk0),
                       end_offset=jnp.asarray(-s * a), contact_stiffness=kc, terms=base.terms,
                       name="end-loaded rod", contact_quadrature=int(contact_quadrature))
    return rod if contact_stiffness is None else rod.with_terms("contact")


def with_material(scene, material):
    """``scene`` with its material replaced (a shallow copy: the same compiled programs, the
    material's stiffnesses being leaves)."""
    if not isinstance(material, Material):
        raise TypeError(f"material must be a jaxrod.model.material.Material, got {type(material).__name__}")
    new = copy.copy(scene)
    object.__setattr__(new, "material", material)
    return new


def check_scene(scene):
    if not isinstance(scene, EndLoadedRod):
        raise TypeError(f"scene must be an EndLoadedRod (jaxrod.studies.endloads.shortened_rod), got {type(scene).__name__}")


def check_q(scene, name, q):
    q = np.asarray(q, dtype=float)
    if q.shape != (scene.n_dof,):
        raise ValueError(f"{name} must have shape ({scene.n_dof},) (the scene's DOFs), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError(f"{name} must be finite")
    return q
