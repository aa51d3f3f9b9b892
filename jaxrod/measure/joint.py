"""The joint of a twisted closed rod: where the line drawn on a rod whose ends were turned by phi
before gluing jumps by -phi (mod 2 pi), how large the jump is, and the twist it hides (step 8 of
``jaxrod.measure.analysis.analyze``)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.topology import is_whole_turns

TWO_PI = 2.0 * math.pi

# A jump of the eccentric line's angle at one place (the joint of a closed rod twisted by a
# non-whole number of turns) counts when it exceeds this many turns in all and its largest step
# stands out of the step-to-step variation of the turning angles by this factor (robust scale).
_JUMP_MIN_TURNS = 0.01
_JUMP_CONTRAST = 10.0
# joint_twist given: a jump left over (the line's jump plus the twist accounted for) beyond this
# many turns means joint_twist does not describe this line.
_JUMP_MISMATCH_TURNS = 0.05


def _closure_jump(angles, width):
    """The largest localised jump of the turning angles ``angles`` (n,) of a closed sequence of
    frames (angle i across node i), over their smooth trend.

    The jump is located at the largest three-point spike |a_i - (a_{i-1} + a_{i+1})/2|. Around it,
    a window of half-width w (from ``width``, the expected spread of an interpolant's ringing,
    widened by half at a time until the excess has died out in the window's outer quarter, at most
    (n - 1)/4); the trend is a quadratic fitted to the steps w to 2w away on either side, and the
    jump is the sum of the excess over it within the window. Returns (jump (radians), lo, hi: the
    first and last step (circular indices, lo <= hi) whose excess stands out, peak: the step of
    largest excess (mod n), significant: the jump exceeds 0.01 turn and its spike stands out of the
    step-to-step variation by ``_JUMP_CONTRAST``)."""
    a = np.asarray(angles, dtype=float)
    n = a.size
    if n < 9:
        return 0.0, 0, 0, 0, False
    spike = np.abs(a - 0.5 * (np.roll(a, 1) + np.roll(a, -1)))
    scale = 1.4826 * float(np.median(spike))  # robust scale of the smooth (or noisy) variation
    k = int(np.argmax(spike))
    top = (n - 1) // 4
    w = int(min(max(width, 2), top))
    while True:
        near = np.arange(k - w, k + w + 1)
        flanks = np.concatenate([np.arange(k - 2 * w, k - w), np.arange(k + w + 1, k + 2 * w + 1)])
        trend = np.polyfit(flanks - k, a[flanks % n], 2)
        excess = a[near % n] - np.polyval(trend, near - k)
        biggest = float(np.max(np.abs(excess)))
        level = max(0.5 * _JUMP_CONTRAST * scale, 0.005 * biggest)
        rim = np.abs(excess[np.abs(near - k) > 0.75 * w])
        if w >= top or rim.size == 0 or float(np.max(rim)) <= max(level, 0.02 * biggest):
            break
        w = min(top, max(w + 1, int(1.5 * w)))
    jump = float(np.sum(excess))
    out = np.flatnonzero(np.abs(excess) > level)
    lo, hi = (int(near[out[0]]), int(near[out[-1]])) if out.size else (k, k)
    peak = int(near[np.argmax(np.abs(excess))] % n)
    significant = abs(jump) > TWO_PI * _JUMP_MIN_TURNS and spike[k] > _JUMP_CONTRAST * scale
    return jump, lo, hi, peak, bool(significant)


def _smooth_joint(tau, h, lo, hi, residual):
    """tau with the spike of a jump across steps lo..hi removed: the nodes lo-1..hi+1 get the
    straight line between their neighbours plus ``residual`` (radians: the joint step's twist
    beyond the trend) spread evenly over them; with too few nodes left, ``residual`` is spread
    over all nodes instead."""
    n = tau.size
    tau = np.array(tau)
    nodes = np.arange(lo - 1, hi + 2)
    if nodes.size + 4 > n:
        return tau + residual / (n * h)
    left, right = tau[(lo - 2) % n], tau[(hi + 2) % n]
    w = (nodes - lo + 2) / (nodes.size + 1.0)
    tau[nodes % n] = (1.0 - w) * left + w * right + residual / (nodes.size * h)
    return tau


@dataclass(frozen=True)
class JointReading:
    """What the joint of a closed rod says (``read_joint``): jump_turns, the jump of the line's
    angle at the joint (turns; 0.0 where none stands out); line_closes, whether the line closes
    onto itself (the Gauss linking number is defined); notes, the warnings; hidden, the turn the
    jump hides (radians, added to Tw; 0.0 without ``joint_twist``); tau, the twist density with
    the joint's spike removed where ``hidden`` is accounted for (else the one given)."""

    jump_turns: float
    line_closes: bool
    notes: tuple
    hidden: float
    tau: np.ndarray


def read_joint(angles, tau, s, h, width, joint_twist):
    """``JointReading`` of a closed rod from the turning angles ``angles`` (n,) of its frames, its
    twist density ``tau`` (n,) at the nodes of arc length ``s`` (n,) spaced ``h``; ``width``: the
    expected spread of the jump (``_closure_jump``); ``joint_twist``: the imposed twist phi
    (radians) or None. The turn hidden in the jump is phi - 2 pi m, m the integer that leaves the
    joint step nearest the trend; the rest of the jump beyond the trend is spread over the nodes
    spanning it (``_smooth_joint``), or over all nodes where no jump stands out."""
    jump, lo, hi, peak, found = _closure_jump(angles, width)
    jump_turns = jump / TWO_PI if found else 0.0
    where = f"at s = {s[peak]:.4g} (node {peak})"
    if joint_twist is None:
        notes = (_unclosed_note(jump, where),) if found else ()
        return JointReading(jump_turns, not found, notes, 0.0, tau)
    line_closes = not found and is_whole_turns(joint_twist)
    hidden = joint_twist - TWO_PI * math.floor((joint_twist + jump) / TWO_PI + 0.5)
    residual = jump + hidden  # what the joint step still turns beyond the trend
    notes = ()
    if abs(residual) > TWO_PI * _JUMP_MISMATCH_TURNS:
        seen = f"jumps by {jump / TWO_PI:+.4f} turns {where}" if found else "closes smoothly"
        notes = (f"eccentric: joint_twist = {joint_twist:.6g} rad ({joint_twist / TWO_PI:.4g} turns) does not match "
                 f"the line, which {seen}: a line on a rod twisted by phi jumps by -phi mod 1 turn at the joint, so "
                 f"{residual / TWO_PI:+.4f} turns are left unexplained; check the value and sign of joint_twist",)
    if hidden != 0.0:
        if found:
            tau = _smooth_joint(tau, h, lo, hi, residual)
        else:  # nowhere to put it but everywhere
            tau = tau + hidden / (tau.size * h)
    return JointReading(jump_turns, line_closes, notes, hidden, tau)


def _unclosed_note(jump, where):
    """The warning for a line that jumps at the joint when no joint twist was given."""
    return (f"eccentric: the line does not close onto itself: its angle about the centreline jumps by "
            f"{jump / TWO_PI:+.4f} turns {where}, far more than between neighbouring nodes (a rod twisted "
            "by a non-whole number of turns before its ends were glued?); Tw and Lk from the frames miss "
            "that fractional turn, tau spikes there and the Gauss linking number is not defined (NaN): "
            "give the imposed twist as joint_twist= (radians; the CLI's --joint-twist, which a step file's phi "
            "supplies)")
