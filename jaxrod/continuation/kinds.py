"""What a continuation reports where a branch changes: one ``EventKind`` for both engines.

The pseudo-arclength engine reports ``FOLD``, ``BRANCH_POINT``, ``SOFT_FOLD`` and ``SOFT_TURN``;
the stable-only follower ``UNSTABLE`` and ``JUMP`` (see ``EventKind``).
"""
from __future__ import annotations

import enum

__all__ = ["EventKind", "SHAPE_EVENTS", "SOFT_EVENTS"]


class EventKind(str, enum.Enum):
    """Where a branch changes: the kind of an event located at a twist phi (rad) of a path.

    A ``str``: each member compares equal to, prints and formats as its value ("fold",
    "branch_point", ...), which is what studies write to JSON.

    Attributes
    ----------
    FOLD : str
        "fold": the path turns back in the parameter, an eigenvalue crossing zero.
    BRANCH_POINT : str
        "branch_point": the Morse index changes without a fold.
    SOFT_FOLD : str
        "soft_fold": a turn along a soft (sliding) mode, Morse index unchanged.
    SOFT_TURN : str
        "soft_turn": a turn along soft directions with no singular point to locate.
    UNSTABLE : str
        "unstable": a followed stable branch acquired a negative eigenvalue (``follow_twist``).
    JUMP : str
        "jump": the minimiser following a stable branch left it (a fold, or a subcritical
        bifurcation; ``follow_twist``).
    """

    FOLD = "fold"  # the path turns back in the parameter, an eigenvalue crossing zero
    BRANCH_POINT = "branch_point"  # the Morse index changes without a fold
    SOFT_FOLD = "soft_fold"  # a turn along a soft (sliding) mode, Morse index unchanged
    SOFT_TURN = "soft_turn"  # a turn along soft directions with no singular point to locate
    UNSTABLE = "unstable"  # a followed stable branch acquired a negative eigenvalue
    JUMP = "jump"  # the minimiser following a stable branch left it

    def __str__(self):
        return self.value

    def __format__(self, spec):
        return format(self.value, spec)


# The located kinds that change the shape's stability (the instabilities a study reports).
SHAPE_EVENTS = (EventKind.FOLD, EventKind.BRANCH_POINT)
# The turns along sliding modes, which a knot's path slides across.
SOFT_EVENTS = (EventKind.SOFT_FOLD, EventKind.SOFT_TURN)
