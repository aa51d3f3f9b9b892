"""A rough error estimate for one twist study: each side's first branch end found again at the
coarser level N_c = (N + 1) / 2, then two-level Richardson (``coarse_companion``); and the check
that such a level resolves the rod (``coarse_level``)."""
from __future__ import annotations

import math

import numpy as np

from .accuracy import level_of_side, refine_scene, richardson

__all__ = ["CoarseLevelTooSmall", "coarse_level", "CoarseEstimates", "coarse_companion"]


class CoarseLevelTooSmall(ValueError):
    """The coarse level (N + 1) / 2 of an error estimate would be below the rod's resolution."""


def coarse_level(scene):
    """N_c = (N + 1) / 2, the coarse level of an error estimate for a rod of N nodes, or ``CoarseLevelTooSmall``
    when N_c is below the rod's resolution (8 nodes; a knot: 24, and L/D: no edge longer than D)."""
    N = int(scene.n_nodes)
    N_c, need = (N + 1) // 2, 8
    if scene.has_term("contact"):
        need = max(24, math.ceil(float(scene.length) / float(scene.material.D) - 1e-9))
    if N_c < need:
        raise CoarseLevelTooSmall(f"no error estimate from N = {N_c}: the coarse level needs at least {need} nodes "
                                  f"(N = {N} would have to be at least {2 * need - 1})")
    return N_c


class CoarseEstimates(dict):
    """{side: (Level, Extrapolation)} of ``coarse_companion``, and ``reasons``: {side: why there is
    no estimate} for each side asked for that has none."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.reasons = {}


def coarse_companion(scene, out, critical, span=16 * math.pi, step=0.5 * math.pi, tol=None, margin=0.5 * math.pi,
                     progress=None, cancel=None, sides=("plus", "minus")):
    """An error estimate for a finished twist study (``jaxrod.studies.twist.twist_study`` in ``out``, of the
    closed rod ``scene`` at N nodes): each side's first branch end found again at the coarser
    N_c = (N + 1) / 2 (every coarse node a node of the study's rod), started from the study's own
    state ``margin`` before its end, resampled; then two-level Richardson (order 2 assumed,
    Roache's factor 3). Cheap and deliberately rough: how far the study's phi* may be from the
    converged value (``converged_critical_twists`` measures the order). cancel: an optional
    threading.Event; once set, the run stops at its next continuation point (raising
    ``Cancelled``). It reads only the study's step files and ``critical``'s instabilities, so it
    may run beside the diagram. sides: the sides to estimate. Returns a ``CoarseEstimates``,
    {side: (Level, Extrapolation)}, whose ``reasons`` say why each other side asked for has none. Raises
    ``CoarseLevelTooSmall`` when N_c is below the rod's resolution (8 nodes; a knot: 24, and L/D)."""
    import glob
    import os

    from ..solve.equilibrium import relax_to_minimum

    say = progress or (lambda s: None)
    N, N_c = int(scene.n_nodes), coarse_level(scene)
    tol = critical.get("tol") if tol is None else tol
    found = CoarseEstimates()
    for side in sides:
        if side not in ("plus", "minus"):
            raise ValueError(f"sides: 'plus' or 'minus', got {side!r}")
        first = [c for c in critical["instabilities"] if c["direction"] == side]
        if not first:
            found.reasons[side] = "the study found no branch end on this side"
            continue
        phi_star, branch = first[0]["phi"], first[0]["from_branch"]
        phi_error = float(first[0].get("phi_error", 0.0))
        target = abs(phi_star) - margin
        best = None
        for path in sorted(glob.glob(os.path.join(out, "steps", f"{side}_*.npz"))):
            with np.load(path) as f:
                if str(f["branch"]) == branch and abs(float(f["phi"])) <= target:
                    best = (float(f["phi"]), np.asarray(f["q"]))
        if best is None:
            found.reasons[side] = f"no step of {branch} on file {margin / math.pi:.3g} pi or more before its end"
            continue
        phi_start, q = best
        coarse = refine_scene(scene, np.asarray(q)[: 3 * N].reshape(N, 3), N_c)
        q0 = np.array(coarse.q_init)
        q0[3 * N_c:] += phi_start * np.arange(N_c) / N_c
        start = relax_to_minimum(coarse, phi_start, q0=q0)
        level, reason, _ = level_of_side(coarse, side, phi_start, start, span, step, tol or 1e-3 * math.pi, say, cancel)
        if level is None:
            say(f"{side}: no estimate from N = {N_c}: {reason}")
            found.reasons[side] = reason
            continue
        found[side] = (level, richardson([N_c, N], [level.phi_star, phi_star], [level.phi_error, phi_error]))
    return found
