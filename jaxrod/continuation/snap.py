"""Where a stable branch that ended by a jump goes: the snap, with the states on both sides.

A stable-only path ends in a ``JUMP`` where its corrector, stepping ever more finely, still leaves
the branch for a state more than ``jump_tol`` away, and no eigenvalue was seen crossing zero. In a
smooth energy the branch then ends at a fold that the extended system locates; where it does not
(the fold hides inside the near-zero band of the sliding modes, or lies closer to the jump than
roundoff resolves), the end is a *snap*: within the bracket the rod jumps from its last stable
state to another stable state at nearly the same twist. ``snap_of`` finds that other state by the
rule of branch switching (``switching.SWITCH_RULE``: of the stable states away from the branch, with
Lk kept, the lowest in energy) and returns both.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..model.geometry import polyline_distance
from ..solve.equilibrium import Equilibrium
from .kinds import EventKind
from .options import Task, checked_options

__all__ = ["Snap", "snap_of"]


@dataclass(frozen=True)
class Snap:
    """A branch end at which the rod jumps to another stable state.

    phi_before: the last stable twist on the branch (rad); phi: the twist at which it jumps (the
    bracket's far end, within ``phi - phi_before`` of the end); before, after: the two stable
    ``Equilibrium`` states (after at ``phi``); energy_change: E(after) - E(before) (the energy at
    phi_before and phi differ by the work of the twist over the bracket as well); moved: the largest
    distance of a node of ``after`` from the centreline of ``before`` (blind to sliding along it);
    choice: how ``after`` was chosen (``switching.SWITCH_RULE`` and what each start reached).
    """

    phi_before: float
    phi: float
    before: Equilibrium = field(repr=False)
    after: Equilibrium = field(repr=False)
    energy_change: float
    moved: float
    choice: dict = field(default_factory=dict, repr=False)

    def summary(self):
        """The snap in words, for a table's reason column."""
        return (f"snaps between {self.phi_before / math.pi:+.8f} and {self.phi / math.pi:+.8f} pi to a stable state "
                f"{self.moved:.3g} away (energy change {self.energy_change:+.3e}, Wr {self.before.Wr:+.4f} -> "
                f"{self.after.Wr:+.4f})")

    def arrays(self):
        """Both states as arrays (for an .npz): q_before, phi_before, q_after, phi_after."""
        return {"q_before": np.asarray(self.before.q), "phi_before": np.float64(self.phi_before),
                "q_after": np.asarray(self.after.q), "phi_after": np.float64(self.phi)}


def snap_of(scene, path, options=None, progress=None):
    """The snap at the end of ``path`` (a ``TwistPath`` of ``scene``, run with ``options``), or
    None where its first end is not a ``JUMP`` or no stable state away from the branch is found at
    the bracket's far end. The last stable state and its tangent are the path's last point before
    the end."""
    from .follow import _follow_engine
    from .switching import _switch_branch

    if not path.instabilities or path.instabilities[0].kind is not EventKind.JUMP:
        return None
    inst = path.instabilities[0]
    point = next((p for p in reversed(path.points) if p.equilibrium is inst.equilibrium), None)
    if point is None or point.tangent is None:
        return None
    phi_before, phi = (float(b) for b in inst.bracket)
    opts = checked_options(options).resolved(scene, Task.FOLLOW_TWIST, max(abs(phi), math.pi))
    engine = _follow_engine(scene, opts)
    found, choice = _switch_branch(engine, point.equilibrium, np.asarray(point.tangent), phi, inst.mode, None,
                                   progress or (lambda line: None))
    if found is None:
        return None
    before, after = point.equilibrium, found.equilibrium
    return Snap(phi_before, phi, before, after, float(after.energy - before.energy),
                polyline_distance(np.asarray(after.x), np.asarray(before.x), bool(getattr(scene, "closed", True))),
                choice)
