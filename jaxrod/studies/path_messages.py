"""What a branch end's path says, in words: the engine's stop reasons with the twist in multiples
of pi (as the results give it), and the sentences that go beside a located end."""
from __future__ import annotations

import math
import re

__all__ = ["twist_message", "end_message", "extra_crossings"]


def _twist_text(match):
    return f"phi = {float(match.group(1)) / math.pi:+.8f} pi"


def _range_text(match):
    return f"[{float(match.group(1)) / math.pi:+.6f}, {float(match.group(2)) / math.pi:+.6f}] pi"


# a number as the engine formats p (``:g``, ``:.12g``): no trailing full stop taken
_NUMBER = r"([-+]?(?:inf|nan|\d+(?:\.\d+)?(?:e[-+]?\d+)?))"


def twist_message(branch):
    """A pseudo-arclength path's stop reason with the engine's 'p = 20.7' written 'phi = +6.58915549 pi'
    and a range '[-inf, 24.3]' as '[-inf, +7.734930] pi'."""
    text = re.sub(r"\bp = " + _NUMBER, _twist_text, branch.message)
    return re.sub(r"\[" + _NUMBER + ", " + _NUMBER + r"\]", _range_text, text)


def end_message(end, branch):
    """What a path that located its end ``end`` (a converged Event) says: the stop rule's message
    where it stopped by it, else that the end was located, then what went wrong past it."""
    from ..continuation.arclength.results import Result

    message = twist_message(branch)
    if branch.result is Result.STOPPED:
        return message
    return f"{end.kind} located at {end.p / math.pi:+.8f} pi; past it: {message}"


def extra_crossings(ev):
    """A sentence when the located event ``ev`` changes the Morse index by more than its
    multiplicity: another eigenvalue crossed zero within the same step (a near-double event); else ''."""
    jump = int(ev.morse_after) - int(ev.morse_before)
    if jump <= int(ev.multiplicity):
        return ""
    return (f"the {ev.kind} located at {ev.p / math.pi:+.8f} pi changes the Morse index by {jump} "
            f"({ev.morse_before} -> {ev.morse_after}), more than its multiplicity {ev.multiplicity}: another "
            "eigenvalue crosses zero within the same step (a near-double event); phi* is this event's, the "
            "crossing next to it is not located")
