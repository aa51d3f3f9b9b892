"""Whether a branch end located on the extended system is the study's first instability.

The diagram (``jaxrod.studies.diagram``) follows the study's branch by pseudo-arclength in a
pinned gauge and locates the first fold or branch point on its path; where two singular points lie
close together, that path may meet the second one first. ``verify_end`` says which eigenvalue
vanishes at the located state in the study's own gauge, whether every other one is still positive
(the zero is the branch's first), its overlap with the study's critical mode and its parity.
``onset_events`` orders the study's bracket and the extended system's event as the branch meets them.
"""
from __future__ import annotations

import math

import numpy as np

from ..linalg.stability import stability
from ..model.symmetry import SYMMETRIC_TOL, joint_two_fold, symmetrize

__all__ = ["verify_end", "study_mode", "onset_events", "VANISHING_EIGENVALUE"]
# ``verify_end``'s default band (scaled units): a located end's critical eigenvalue is ~1e-14.
VANISHING_EIGENVALUE = 1e-10


def study_mode(scene, q, phi, eigenvalue, k=6):
    """(n,) the unit eigenvector (scaled DOFs) at the study's last stable state (q, phi) whose
    eigenvalue, of the k lowest, is nearest the recorded critical ``eigenvalue``."""
    st = stability(scene, np.asarray(q, dtype=float), float(phi), k=k)
    j = int(np.argmin(np.abs(np.asarray(st.eigenvalues) - eigenvalue)))
    return np.asarray(st.eigenvectors[:, j])


def _parity(scene, q, v):
    """+1 (even) or -1 (odd) for the mode v (scaled DOFs) under the two-fold symmetry through the
    joint that the state q (physical DOFs) has; None where q has no such symmetry."""
    edge = float(scene.length) / scene.n_nodes
    sym = joint_two_fold(scene, q, SYMMETRIC_TOL * edge)
    if sym is None:
        return None
    dq = np.asarray(scene.from_scaled(v), dtype=float)
    eps = 1e-6 / max(float(np.max(np.abs(dq))), 1e-300)
    # the map is affine: S(q + eps dq) - S(q) = eps S dq, with S(q) = 2 symmetrize(q) - q
    image = (2.0 * symmetrize(scene, q + eps * dq, sym) - (q + eps * dq)) - (2.0 * symmetrize(scene, q, sym) - q)
    c = float(np.dot(image, dq) / (eps * np.dot(dq, dq)))
    return 1 if c > 0.0 else -1


def verify_end(scene, q, phi, reference_mode, band=VANISHING_EIGENVALUE, k=6):
    """What vanishes at the located state (q (n,) physical DOFs, phi), zero modes projected out as
    the study does, and whether the state is otherwise stable there. reference_mode: (n,) the study's critical eigenvector (``study_mode``), or None; band: the
    study's near-zero band (``negative_tol``): an eigenvalue inside it vanishes. Returns a dict:
    eigenvalue_index (of the k lowest, the one nearest zero), eigenvalue, vanishes (|eigenvalue| <=
    band), first (no other eigenvalue below -band), overlap (of the vanishing mode with the
    reference, or None), parity ('even', 'odd' under the joint's two-fold symmetry, or None)."""
    q = np.asarray(q, dtype=float)
    st = stability(scene, q, float(phi), k=k)
    lam, vec = np.asarray(st.eigenvalues), np.asarray(st.eigenvectors)
    j = int(np.argmin(np.abs(lam)))
    overlap = None if reference_mode is None else float(abs(vec[:, j] @ np.asarray(reference_mode, dtype=float)))
    others = np.delete(lam, j)
    parity = _parity(scene, q, vec[:, j])
    return {"eigenvalue_index": j, "eigenvalue": float(lam[j]), "vanishes": bool(abs(lam[j]) <= band),
            "first": bool(not np.any(others < -band)), "overlap": overlap,
            "parity": None if parity is None else ("even" if parity > 0 else "odd")}


def onset_events(instability, event):
    """What is known of one side's first instability, in the order the branch meets it: a list
    of dicts (kind, phi, phi_over_pi, located, source: 'study' or 'extended system'). The event
    alone where it is confirmed as the onset; else both, in branch order (the study's jump named a
    'snap' where the study switched to a stable branch beyond it, whose state its ``*_after``
    fields give). instability: the study's critical.json entry; event: the diagram's event dict
    for it, or None."""
    kind = instability.get("kind")
    if str(kind) == "jump" and instability.get("to_branch"):
        kind = "snap"  # the rod jumps to the stable branch the study switched to (its *_after fields)
    study = {"kind": kind, "phi": instability["phi"], "phi_over_pi": instability["phi"] / math.pi,
             "phi_error": instability.get("phi_error"), "located": False, "source": "study"}
    if event is None or event.get("phi") is None:
        return [study]
    located = {"kind": event.get("kind"), "phi": event["phi"], "phi_over_pi": event["phi"] / math.pi,
               "phi_error": None if event.get("located") else instability.get("phi_error"),
               "located": bool(event.get("located")), "source": "extended system"}
    if event.get("confirmed"):
        return [located]
    sign = 1.0 if instability["direction"] == "plus" else -1.0
    return sorted([study, located], key=lambda d: sign * d["phi"])
