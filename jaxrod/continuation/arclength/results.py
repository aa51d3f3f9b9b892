"""Results: points, events and branches, with result codes (never parsed from messages)."""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np


class Result(enum.Enum):
    """How a continuation (or an event location) ended."""

    BOUNDARY = "left [p_min, p_max]"
    MAX_STEPS = "max_steps reached"
    CORRECTOR_FAILED = "corrector failed with a step below ds_min"
    LOCATION_FAILED = "an event was detected but not located to event_tol"
    STOPPED = "stopped by the caller's rule (``continuation_until``)"


class ContinuationError(RuntimeError):
    """Raised with ``throw=True``; ``.branch`` holds what was computed before the failure."""

    def __init__(self, message, branch):
        super().__init__(message)
        self.branch = branch


@dataclass
class Point:
    """One converged point. u (n,), tangent (n+1,) unit, last component dp/ds; eigenvalues
    (k,) ascending and eigenvectors (n, k), zero modes removed; arclength from the start."""

    u: np.ndarray
    p: float
    tangent: np.ndarray
    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    morse_index: int
    iterations: int
    ds: float
    arclength: float
    soft: np.ndarray = None  # (k,) bool: soft modes (``BifurcationProblem.soft_modes``), not in morse_index

    @property
    def z(self):
        return np.append(self.u, self.p)

    @property
    def bordered_sign(self):
        """sign det [[J, F_p], [t_u^T, t_p]] = (-1)^morse sign(t_p): the classic branch-point test
        function (it changes at a simple branch point, not at a fold nor a double branch point)."""
        return (-1) ** self.morse_index * (1 if self.tangent[-1] >= 0 else -1)


@dataclass
class Event:
    """A located fold or branch point between points ``step - 1`` and ``step`` of its branch.

    u (n,), v (n, multiplicity) approximate orthonormal kernel, eigenvalues (multiplicity,) the
    critical eigenvalues; residual and iterations: of the extended system (or the corrector, and
    Brent's eigenvalue evaluations); tangent (n+1,) of the parent branch at the nearest bracket
    end; converged: residual and critical eigenvalues <= options.event_tol.
    """

    kind: str
    p: float
    u: np.ndarray
    v: np.ndarray
    eigenvalues: np.ndarray
    residual: float
    iterations: int
    multiplicity: int
    morse_before: int
    morse_after: int
    step: int
    tangent: np.ndarray
    converged: bool

    @property
    def critical_eigenvalue(self):
        return float(np.max(np.abs(self.eigenvalues)))


@dataclass
class Slide:
    """A jump across a soft fold (``soft_folds = "slide"``): from the located ``fold`` to the minimum
    ``u`` (n,) reached at p; distance |u - fold.u|, energy_drop E(fold.u, p) - E(u, p) (>= 0),
    iterations of the relaxation; ``step``: the index of the point it arrived at."""

    fold: Event
    p: float
    u: np.ndarray
    distance: float
    energy_drop: float
    iterations: int
    step: int


@dataclass
class Branch:
    """Points in path order, located events, how it ended (``result``, ``message``), and
    ``origin``: how it was started (e.g. the emanating direction after a branch switch);
    ``slides``: the jumps made across soft folds (``Slide``), in path order."""

    points: list
    events: list
    result: Result
    message: str = ""
    origin: dict = field(default_factory=dict)
    slides: list = field(default_factory=list)

    @property
    def p(self):
        return np.array([q.p for q in self.points])

    @property
    def u(self):
        return np.array([q.u for q in self.points])

    @property
    def morse_index(self):
        return np.array([q.morse_index for q in self.points])

    def events_of(self, kind):
        return [e for e in self.events if e.kind == kind]
