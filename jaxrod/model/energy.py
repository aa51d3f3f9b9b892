"""Energy terms of a discrete elastic rod (Bergou et al. 2008 style), each a small pure function.

Scenes compose the terms they need (``jaxrod.model.scenes``). All functions are jittable and twice
differentiable wherever the rod has no hairpin (antiparallel consecutive edges).

Shapes: ``x`` (N,3) nodes; ``rest_lengths`` (M,) with M = N (closed) or N-1 (open);
``vertex_twists`` (K,) and ``voronoi`` (K,) for the K vertices that carry bending and twist.
"""
from __future__ import annotations

import jax.numpy as jnp

from .geometry import curvature_binormals, edges

__all__ = ["stretch_energy", "bend_energy", "twist_energy", "vertex_curvature_binormals"]


def stretch_energy(x, rest_lengths, EA, closed):
    """Sum over edges of (EA/2) l (|e|/l - 1)^2: Hookean axial strain energy."""
    length = jnp.linalg.norm(edges(x, closed), axis=-1)
    strain = length / rest_lengths - 1.0
    return 0.5 * EA * jnp.sum(rest_lengths * strain**2)


def vertex_curvature_binormals(x, closed):
    """Curvature binormals (K,3) at the bending vertices: all N vertices of a closed rod
    (vertex i between edges i-1 and i), the N-2 interior vertices of an open rod."""
    e = edges(x, closed)
    if closed:
        return curvature_binormals(jnp.roll(e, 1, axis=0), e)
    return curvature_binormals(e[:-1], e[1:])


def bend_energy(x, voronoi, B, closed):
    """Isotropic bending of a naturally straight rod: sum over vertices of B |kb|^2 / (2 l_v). |kb|
    / l_v is the discrete curvature at the vertex, l_v its Voronoi (rest) length."""
    kb = vertex_curvature_binormals(x, closed)
    return 0.5 * B * jnp.sum(jnp.sum(kb * kb, axis=-1) / voronoi)


def twist_energy(vertex_twists, voronoi, C):
    """Sum over vertices of C m^2 / (2 l_v), m the twist angle accumulated across the vertex."""
    return 0.5 * C * jnp.sum(vertex_twists**2 / voronoi)
