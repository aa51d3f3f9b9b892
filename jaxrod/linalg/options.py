"""Options for the linear algebra of a rod's Hessian, and which backend they pick for a scene.

Kept apart from the backends (``jaxrod.linalg.backend``) so every linear-algebra module can ask."""
from __future__ import annotations

import math
from dataclasses import dataclass

from .tolerances import DEFAULT_NEGATIVE_TOL

__all__ = ["LinalgOptions", "BACKEND_NAMES", "SPARSE_MIN_DOF", "preferred_backend", "backend_name", "has_contact"]

BACKEND_NAMES = ("auto", "dense", "banded", "sparse")

# "auto" takes an O(n) backend from this many DOFs on (N ~ 250 nodes); below it the dense path is
# fast enough, and compiled already for most small scenes.
SPARSE_MIN_DOF = 1000


@dataclass(frozen=True)
class LinalgOptions:
    """How the linear algebra of a rod's Hessian is done (checked on construction).

    backend: "dense", "banded" (rods without contact), "sparse" (the O(n) path: the sparse LDL^T
      with contact, the banded one without), or "auto" (dense below ``sparse_min_dof`` DOFs, the
      O(n) path from there on).
    sparse_min_dof: where "auto" switches to the O(n) path (default 1000 DOFs).
    negative_tol: an eigenvalue of the projected Hessian counts as negative below -negative_tol
      (dimensionless, scaled energy; default 1e-10).
    eig_tol: the banded eigensolver's residual tolerance, relative to a bound on ||H||
      (default 1e-12).
    """

    backend: str = "auto"
    sparse_min_dof: int = SPARSE_MIN_DOF
    negative_tol: float = DEFAULT_NEGATIVE_TOL
    eig_tol: float = 1e-12

    def __post_init__(self):
        if self.backend not in BACKEND_NAMES:
            raise ValueError(f"backend must be one of {BACKEND_NAMES}, got {self.backend!r}")
        if not (isinstance(self.sparse_min_dof, int) and self.sparse_min_dof >= 0):
            raise ValueError(f"sparse_min_dof must be an int >= 0, got {self.sparse_min_dof!r}")
        for name in ("negative_tol", "eig_tol"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {value!r}")


def has_contact(scene):
    """Whether the scene has the contact term."""
    return scene.has_term("contact")


def preferred_backend(scene, options):
    """(name, reason) of the backend the options ask for on this scene, before what the caller
    offers is taken into account."""
    contact = has_contact(scene)
    n = int(scene.n_dof)
    if options.backend == "dense":
        return "dense", "dense asked for"
    if options.backend == "banded":
        if contact:
            raise ValueError("backend 'banded' cannot hold contact (its pair blocks couple distant nodes): use "
                             "'sparse' or 'dense'")
        return "banded", "banded asked for"
    if options.backend == "sparse":
        if contact:
            return "sparse", "sparse asked for"
        return "banded", "O(n) asked for, no contact: the banded block LDL^T is the O(n) path"
    if n < options.sparse_min_dof:
        return "dense", f"auto: {n} DOFs, below {options.sparse_min_dof}"
    if contact:
        return "sparse", f"auto: {n} DOFs >= {options.sparse_min_dof}, with contact"
    return "banded", f"auto: {n} DOFs >= {options.sparse_min_dof}, no contact"


def backend_name(scene, options=None, offered=("dense", "banded", "sparse")):
    """(name, reason): the backend ``options`` (a ``LinalgOptions``, a backend name or None for
    the defaults) pick for ``scene`` among those ``offered`` by the caller; where the preferred
    one is not offered, "dense", and the reason says so."""
    if options is None:
        options = LinalgOptions()
    elif isinstance(options, str):
        options = LinalgOptions(backend=options)
    name, reason = preferred_backend(scene, options)
    if name not in offered:
        name, reason = "dense", f"{reason}; {name} not offered here: dense"
    return name, reason
