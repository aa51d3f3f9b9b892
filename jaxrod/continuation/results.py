"""What the stable-only continuation returns: ``CriticalPoint`` (``critical_twist``), ``TwistPath``
of ``PathPoint`` and ``Instability`` (``follow_twist``), why a path stopped (``PathStop``) or a
branch ended (an ``EventKind``, ``Instability.kind``), and ``NoCrossingError``."""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from ..solve.equilibrium import Equilibrium
from .kinds import EventKind


class _ValueEnum(str, enum.Enum):
    """A str enum that compares equal to, prints and formats as its value (what studies write
    to JSON)."""

    def __str__(self):
        return self.value

    def __format__(self, spec):
        return format(self.value, spec)


class NoCrossingError(RuntimeError):
    """The negative-eigenvalue count did not change over the scanned range of phi."""


@dataclass(frozen=True)
class CriticalPoint:
    """A twist at which an eigenvalue of the equilibrium branch crosses zero.

    phi: critical twist (rad); eigenvalue: crossing eigenvalue there (~0, dimensionless);
    dlambda_dphi: its derivative along the branch; mode: (n,) critical eigenvector (scaled DOFs);
    equilibrium: the branch state at the last evaluated twist (within phi_error of phi);
    multiplicity: change of the negative count; bracket: (phi_a, phi_b) where the count changed;
    phi_error: size of the last Newton correction (an upper bound on the error once converged);
    hessian_evaluations: spectra computed in the refinement (bracket ends included);
    scan: list of (phi, n_negative, lowest eigenvalues), one entry per scan step.
    """

    phi: float
    eigenvalue: float
    dlambda_dphi: float
    mode: np.ndarray
    equilibrium: Equilibrium
    multiplicity: int
    bracket: tuple
    phi_error: float
    hessian_evaluations: int
    scan: list = field(repr=False)
    seconds: float = 0.0
    scene: object = field(default=None, repr=False)  # the scene as used last (fresh contact list)


@dataclass(frozen=True)
class PathPoint:
    """One accepted continuation step (a point of the path, not a bifurcation): ``equilibrium``
    (with its stability) on the branch named ``branch``; ``tangent``: dq/dphi there (physical
    DOFs, near-zero modes left out); ``scene``: the scene with its contact list valid at this
    state; ``direction``: 'plus' where the path runs towards larger phi, 'minus' towards smaller."""

    branch: str
    equilibrium: Equilibrium
    tangent: np.ndarray = field(repr=False)
    scene: object = field(repr=False)
    direction: str = ""


@dataclass(frozen=True)
class Instability:
    """Where a followed stable branch stops being one.

    phi: estimate inside the bracket (``branch_end_in_bracket``); phi_error: its distance to the
    bracket's far end; bracket: (last stable twist reached, nearest twist where the branch was
    lost); kind: an ``EventKind``, UNSTABLE or JUMP; multiplicity: how many eigenvalues go soft
    together; eigenvalue, dlambda_dphi, mode: the critical eigenvalue at the last stable state,
    its derivative along the branch and its eigenvector (scaled DOFs); equilibrium: that last
    stable state; from_branch / to_branch: branch names (to_branch None without a switch);
    jumped_to: the first state of the new branch (or None); switch: how that branch was chosen
    (a dict, ``switching.SWITCH_RULE``), None where no switch was tried.
    """

    phi: float
    phi_error: float
    bracket: tuple
    kind: EventKind
    multiplicity: int
    eigenvalue: float
    dlambda_dphi: float
    mode: np.ndarray = field(repr=False)
    equilibrium: Equilibrium = field(repr=False)
    from_branch: str = ""
    to_branch: str | None = None
    negative_tol: float = 0.0
    dlambda_dphi_secant: float = math.nan
    jumped_to: Equilibrium | None = field(default=None, repr=False)
    switch: dict | None = field(default=None, repr=False)


class PathStop(_ValueEnum):
    """Why ``follow_twist`` stopped."""

    PHI_STOP = "phi_stop"  # the whole range was covered
    BRANCH_ENDED = "branch_ended"  # a branch ended, and no switch was to be made (switch=False, max_switches)
    NO_STABLE_BRANCH = "no_stable_branch"  # a branch ended and no stable state was found beyond it


@dataclass(frozen=True)
class TwistPath:
    """Result of ``follow_twist``: ``points`` (PathPoint per accepted step, in order),
    ``instabilities`` (Instability per branch end met, its phi in rad), ``stop`` (a ``PathStop``),
    ``reason`` (the same in words, with the twist where it happened), ``seconds``."""

    points: list
    instabilities: list
    reason: str
    seconds: float
    stop: PathStop = PathStop.PHI_STOP

    @property
    def completed(self):
        return self.stop is PathStop.PHI_STOP

