"""The order of a scene's degrees of freedom: one ``DofLayout`` per scene kind and size.

q holds first the free node coordinates, node by node (x, y, z), then the free twist angles,
edge by edge. Which nodes and edges are free depends on the scene's kind:

* ``closed``: every node 0..N-1 and every edge 0..N-1 (edge i joins node i to node i+1 mod N);
* ``clamped``: nodes 2..N-3 and edges 1..N-3 (two nodes and one edge fixed at each clamp);
* ``free``: every node 0..N-1 and every edge 0..N-2.

Everything that depends on that order reads it here (the Hessian's sparsity pattern, the banded
path's block order, the contact blocks' DOF indices).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

__all__ = ["DofLayout", "dof_layout", "layout_of", "scene_kind"]

KINDS = ("closed", "clamped", "free")


@dataclass(frozen=True, eq=False)
class DofLayout:
    """Static (numpy) description of q's layout for one scene kind and number of nodes.

    kind: "closed", "clamped" or "free"; n_nodes: N; n: number of DOFs; cyclic: closed rods (node
    N-1 couples to node 0). x_dof: (N, 3) index in q of each node coordinate, -1 where the node is
    clamped. theta_dof: (M,) index in q of each edge's twist angle (M edges), -1 where it is fixed.
    spans: (n, 2) first and last node touched by each DOF in q order (a coordinate touches its node;
    an edge's twist angle the edge's two nodes, the last one mod N for a closed rod). node_groups:
    the DOFs in rod order grouped by node, each node's 3 coordinates with the twist angle of one
    edge at that node (see ``_node_groups``)."""

    kind: str
    n_nodes: int
    n: int
    cyclic: bool
    x_dof: np.ndarray
    theta_dof: np.ndarray
    spans: np.ndarray
    node_groups: tuple


def _free_nodes_and_edges(kind, n_nodes):
    """(free nodes, free edges, number of edges) of a kind, in rod order."""
    if kind == "closed":
        return np.arange(n_nodes), np.arange(n_nodes), n_nodes
    if kind == "clamped":
        return np.arange(2, n_nodes - 2), np.arange(1, n_nodes - 2), n_nodes - 1
    if kind == "free":
        return np.arange(n_nodes), np.arange(n_nodes - 1), n_nodes - 1
    raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")


def _node_groups(kind, x_dof, theta_dof):
    """The DOFs (q indices) in rod order, grouped by node. closed: (x_i, theta_i) (edge i starts at
    node i); free: the same, x_{N-1} alone at the end; clamped: (theta_{k-1}, x_k) (the edge that
    ENDS at node k), theta_{N-3} alone at the end. Either way any 2 consecutive groups separate what
    comes before them from what comes after."""
    N = x_dof.shape[0]
    xs = [tuple(int(d) for d in x_dof[i]) for i in range(N)]
    th = [int(d) for d in theta_dof]
    if kind == "closed":
        return tuple(xs[i] + (th[i],) for i in range(N))
    if kind == "free":
        return tuple(xs[i] + (th[i],) for i in range(N - 1)) + (xs[N - 1],)
    return tuple((th[k - 1],) + xs[k] for k in range(2, N - 2)) + ((th[N - 3],),)


@functools.lru_cache(maxsize=64)
def layout_of(kind, n_nodes):
    """The ``DofLayout`` of a scene kind with n_nodes nodes (cached)."""
    nodes, edges, n_edges = _free_nodes_and_edges(kind, int(n_nodes))
    n_x = 3 * nodes.size
    x_dof = -np.ones((n_nodes, 3), dtype=int)
    x_dof[nodes] = np.arange(n_x).reshape(-1, 3)
    theta_dof = -np.ones(n_edges, dtype=int)
    theta_dof[edges] = n_x + np.arange(edges.size)
    cyclic = kind == "closed"
    x_spans = np.stack([np.repeat(nodes, 3)] * 2, 1)
    last = (edges + 1) % n_nodes if cyclic else edges + 1
    spans = np.concatenate([x_spans, np.stack([edges, last], 1)])
    return DofLayout(kind=kind, n_nodes=int(n_nodes), n=n_x + edges.size, cyclic=cyclic, x_dof=x_dof,
                     theta_dof=theta_dof, spans=spans, node_groups=_node_groups(kind, x_dof, theta_dof))


def scene_kind(scene):
    """"closed", "clamped" or "free": the layout kind of a scene (TypeError for other objects)."""
    from .scenes import ClampedRod, ClosedRod, FreeRod

    for cls, kind in ((ClosedRod, "closed"), (ClampedRod, "clamped"), (FreeRod, "free")):
        if isinstance(scene, cls):
            return kind
    raise TypeError(f"no DOF layout for {type(scene).__name__}")


def dof_layout(scene):
    """The ``DofLayout`` of a scene (cached per kind and number of nodes)."""
    return layout_of(scene_kind(scene), int(scene.n_nodes))
