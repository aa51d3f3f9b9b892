"""What the fast energy freezes around a state: the neighbour-list pattern of JAX-MD.

The exact energy (``scene.energy(q, phi)``) needs two non-local things: the writhe, which fixes the
2 pi branch of the holonomy (an O(N^2) double sum), and, with self-contact, the segment pairs that
may touch. Both change slowly, so a solver computes them once around a state and passes them in:

    nbr = scene.neighbourhood(q)            # built outside jit (k-d tree, exact writhe)
    scene.energy(q, phi, nbr)               # O(N) + O(candidate pairs), same value as the exact one
    nbr.stale(x)                            # True once a node moved more than skin/2: rebuild

The energy with ``nbr`` is exact while (i) no node has moved more than skin/2 since the build
(checked by ``stale``) and (ii) the writhe has changed by less than 1/2 (checked by the solvers).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .contact import candidate_pairs
from .material import strong_leaf
from .topology import writhe

__all__ = ["Neighbourhood", "NeighbourhoodUpdate", "build_neighbourhood", "WRITHE_DRIFT_LIMIT"]

# The holonomy lift is exact while |Wr - wr_ref| < 1/2; a solve that ends further than this from
# its reference is repeated around the new state (a quarter turn of margin).
WRITHE_DRIFT_LIMIT = 0.25


@dataclass(frozen=True, eq=False)
class Neighbourhood:
    """Frozen non-local data of a rod state (a pytree: every field is a leaf).

    pairs: (P, 2) int32 candidate segment pairs (padding rows are (0, 0)); mask: (P,) bool, real
    pairs; x_built: (N, 3) nodes where the list was built; skin: the list is valid while no node
    moved more than skin/2; wr_ref: writhe of the centreline (closed rods) or of the centreline
    extended along the clamp axis (clamped rods) at the build state."""

    pairs: jnp.ndarray
    mask: jnp.ndarray
    x_built: jnp.ndarray
    skin: jnp.ndarray
    wr_ref: jnp.ndarray

    @property
    def capacity(self):
        return int(self.pairs.shape[0])

    @property
    def n_candidates(self):
        return int(np.sum(np.asarray(self.mask)))

    def stale(self, x, grown=0.0):
        """True (a JAX bool) when some node of x (N, 3) has moved more than skin/2 from x_built (a
        pair could then be closer than D unlisted); never without contact pairs. grown: how much
        the diameter has grown since the build (uses up that much skin). A numpy x is tested in
        numpy (a Python bool: no eager JAX programs)."""
        if self.pairs.shape[0] == 0:
            return jnp.asarray(False)
        if isinstance(x, np.ndarray):
            moved = float(np.max(np.linalg.norm(x - np.asarray(self.x_built), axis=1)))
            return moved > 0.5 * (float(self.skin) - grown)
        moved = jnp.max(jnp.linalg.norm(x - self.x_built, axis=1))
        return moved > 0.5 * (self.skin - grown)

    def update(self, scene, q, phi, grown=0.0):
        """The one place a solver renews its neighbourhood after a solve: rebuilt around the new
        state q (n,) with this list's capacity (grown if needed), and what changed since this one
        was built: a ``NeighbourhoodUpdate`` (each caller keeps its own policy)."""
        new = scene.neighbourhood(q, phi, capacity=self.capacity)
        x = np.asarray(scene.positions(np.asarray(q, dtype=float)))  # on the host: ``stale`` in numpy
        return NeighbourhoodUpdate(new, bool(self.stale(x, grown)), float(new.wr_ref) - float(self.wr_ref))


@dataclass(frozen=True)
class NeighbourhoodUpdate:
    """What ``Neighbourhood.update`` found. nbr: the neighbourhood rebuilt at the new state;
    stale: some node moved more than skin/2 from where the old list was built (a pair could have
    come within D unlisted); drift: the new writhe minus the old reference writhe."""

    nbr: Neighbourhood
    stale: bool
    drift: float

    @property
    def drifted(self):
        """The writhe left the range where the old holonomy lift is exact (WRITHE_DRIFT_LIMIT)."""
        return abs(self.drift) > WRITHE_DRIFT_LIMIT

    @property
    def outdated(self):
        """The old neighbourhood no longer gives the exact energy at the new state: solve again."""
        return self.stale or self.drifted


jax.tree_util.register_pytree_node(
    Neighbourhood,
    lambda n: (tuple(strong_leaf(v) for v in (n.pairs, n.mask, n.x_built, n.skin, n.wr_ref)), None),
    lambda _, c: Neighbourhood(*c),
)


def build_neighbourhood(x, wr, closed, rest_length, D, with_contact, skin=None, capacity=None):
    """A ``Neighbourhood`` around nodes x (N, 3) (numpy) whose writhe is wr. with_contact: build
    candidate pairs (``jaxrod.model.contact.candidate_pairs``), else an empty list. capacity: pad
    the list to this many rows when it fits; it grows (doubling) when it does not."""
    x = np.asarray(x, dtype=float)
    if with_contact:
        cl = candidate_pairs(x, closed, rest_length, D, skin=skin, capacity=capacity)
        pairs, mask, skin = cl.pairs, cl.mask, cl.skin
    else:
        pairs, mask, skin = np.zeros((0, 2), np.int32), np.zeros(0, bool), math.inf
    return Neighbourhood(
        pairs=jnp.asarray(pairs, dtype=jnp.int32), mask=jnp.asarray(mask), x_built=jnp.asarray(x),
        skin=jnp.asarray(float(skin), dtype=jnp.float64), wr_ref=jnp.asarray(float(wr), dtype=jnp.float64),
    )
