"""Where a ``follow_twist`` run stands between two corrector calls (``PathState``, its ``Phase``):
what ``Observer.on_state`` receives and ``follow_twist(resume=...)`` goes on from, stored in an
npz file by ``to_arrays`` / ``PathState.from_arrays`` (exact resume, to the last bit)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..solve.equilibrium import Equilibrium, equilibrium_arrays, equilibrium_from_arrays
from .engine import StepFailure, _Refusal
from .results import PathStop, _ValueEnum


class Phase(_ValueEnum):
    """Where a ``follow_twist`` run stands (``PathState.phase``)."""

    FOLLOW = "follow"  # stepping along the branch
    LOCATE = "locate"  # the branch was lost: shrinking the bracket around its end to tol
    CONFIRM = "confirm"  # the nearest failure was met from further back: retry it from the last state
    END = "end"  # the end is bracketed: locate phi*, then switch branches or stop
    DONE = "done"


@dataclass(frozen=True)
class PathState:
    """Everything a ``follow_twist`` run needs to go on, between two corrector calls.

    ``Observer.on_state`` receives it after every step tried; ``follow_twist(..., resume=state)``
    goes on from it exactly as the uninterrupted run would, to the last bit. ``to_arrays()`` and
    ``PathState.from_arrays(arrays)`` store it in an npz file (stabilities recomputed on load).

    phase; branch ('symmetric+', ...); prev: last stable state, tangent: dq/dphi there; older: the
    state before (or None); h: current step; switches; n_points / n_instabilities reported;
    lost_*: the nearest lost twist, its refusal and state, and where it was tried from; failures /
    successes / probe_held: ``end_trial``'s memory; stop / reason (phase DONE); critical_modes:
    (n, m) eigenvectors of the modes that made the branch unstable, or None.
    """

    phase: Phase
    branch: str
    prev: Equilibrium = field(repr=False)
    tangent: np.ndarray = field(repr=False)
    older: Equilibrium | None = field(default=None, repr=False)
    h: float = 0.0
    switches: int = 0
    n_points: int = 0
    n_instabilities: int = 0
    lost_phi: float = math.nan
    lost_from: float = math.nan
    lost_refusal: _Refusal | None = None
    lost_equilibrium: Equilibrium | None = field(default=None, repr=False)
    failures: int = 0
    successes: int = 0
    probe_held: bool = False
    stop: PathStop | None = None
    reason: str = ""
    critical_modes: np.ndarray | None = field(default=None, repr=False)

    def to_arrays(self):
        """The state as a dict of numpy arrays (for ``np.savez``)."""
        out = {"phase": np.asarray(self.phase.value), "branch": np.asarray(self.branch), "h": np.asarray(self.h)}
        for key in ("switches", "n_points", "n_instabilities", "failures", "successes"):
            out[key] = np.asarray(getattr(self, key), dtype=np.int64)
        out.update(lost_phi=np.asarray(self.lost_phi), lost_from=np.asarray(self.lost_from),
                   probe_held=np.asarray(self.probe_held), stop=np.asarray("" if self.stop is None else self.stop.value),
                   reason=np.asarray(self.reason))
        if self.lost_refusal is not None:
            out["lost_failure"] = np.asarray(self.lost_refusal.failure.value)
            out["lost_detail"] = np.asarray(self.lost_refusal.detail)
            out["lost_predicted"] = np.asarray(self.lost_refusal.predicted)
        if self.critical_modes is not None:
            out["critical_modes"] = np.asarray(self.critical_modes)
        for name in ("prev", "older", "lost_equilibrium"):
            e = getattr(self, name)
            if e is not None:
                out.update(equilibrium_arrays(e, name + "_"))
                out[name + "_analysed"] = np.asarray(e.stability is not None)
        return out

    @classmethod
    def from_arrays(cls, arrays):
        """A state from ``to_arrays``'s dict (or an opened npz); ``follow_twist(resume=...)``
        rebuilds its equilibria."""
        return _StoredPathState(dict(arrays))


@dataclass(frozen=True)
class _StoredPathState:
    """A ``PathState`` as loaded from a file: arrays, equilibria not yet rebuilt."""

    arrays: dict

    def restore(self, engine):
        a = self.arrays

        def equilibrium(name):
            if name + "_y" not in a:
                return None, None
            e = equilibrium_from_arrays(engine.scene, a, name + "_")
            if not bool(a[name + "_analysed"]):
                return e, None
            s = engine.analysed(e)
            return s.equilibrium, s.tangent

        prev, tangent = equilibrium("prev")
        older, _ = equilibrium("older")
        lost, _ = equilibrium("lost_equilibrium")
        refusal = None
        if "lost_failure" in a:
            refusal = _Refusal(StepFailure(str(a["lost_failure"])), str(a["lost_detail"]),
                               predicted=bool(a["lost_predicted"]) if "lost_predicted" in a else False)
        stop = str(a["stop"])
        return PathState(
            phase=Phase(str(a["phase"])), branch=str(a["branch"]), prev=prev, tangent=tangent, older=older,
            h=float(a["h"]), switches=int(a["switches"]), n_points=int(a["n_points"]),
            n_instabilities=int(a["n_instabilities"]), lost_phi=float(a["lost_phi"]), lost_from=float(a["lost_from"]),
            lost_refusal=refusal, lost_equilibrium=lost, failures=int(a["failures"]), successes=int(a["successes"]),
            probe_held=bool(a["probe_held"]), stop=PathStop(stop) if stop else None, reason=str(a["reason"]),
            critical_modes=np.asarray(a["critical_modes"]) if "critical_modes" in a else None,
        )

