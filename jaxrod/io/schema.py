"""The names of the critical twists in the command line's ``--json`` objects (and the files that
hold the same objects: summary.json, michell.json).

One vocabulary, two shapes:

* a record of **one side**, which names its side: ``side``, ``phi_star``, ``phi_star_over_pi``,
  ``phi_error``, ``kind`` (``jaxrod michell``; each row of ``jaxrod atlas`` and of
  ``jaxrod critical-curve``, whose points are located on the extended system and have no
  ``phi_error``; each side's details under ``plus`` / ``minus`` with ``--accuracy``);
* a record of **both sides** of one knot: the same four quantities per side, named
  ``phi_<side><suffix>``: ``phi_plus``, ``phi_plus_over_pi``, ``phi_plus_error``, ``phi_plus_kind``,
  and ``phi_minus``, ... (``jaxrod trefoil`` and ``jaxrod knot``, whichever the mode: the twist
  study, ``--stable-only``, ``--accuracy``).

Every key is always present; a side without an end in the range has null in each of its keys.
Numbers that are not finite are written as null (strict JSON has no NaN or Infinity).
``KEYS`` gives each key's unit and meaning; ``markdown_table()`` is the README's table of them
(``python -m jaxrod.io.schema`` prints it).
"""
from __future__ import annotations

import math

__all__ = ["SIDES", "SIDE_KEYS", "SUFFIXES", "KEYS", "side_key", "side_record", "both_sides", "json_safe",
           "markdown_table"]

SIDES = ("plus", "minus")

# One side's record: key -> (unit, meaning).
SIDE_KEYS = {
    "side": ("name (plus, minus)", "the side of the twist: plus for phi > 0, minus for phi < 0"),
    "phi_star": ("rad", "the critical twist: where the stable branch followed from phi = 0 ends; "
                        "null when it does not end within the range"),
    "phi_star_over_pi": ("1", "phi_star / pi"),
    "phi_error": ("rad", "the critical twist lies within phi_star +- phi_error: the bracket of a continuation, "
                         "the estimated error with --accuracy, the last Newton step for michell; null where the "
                         "end was located on its extended system (to the solver's tolerance) or none was found"),
    "kind": ("name", "how the branch ends: fold or branch_point (located on the extended system), snap (the "
                     "rod jumps to another stable state inside the bracket; both states are given), jump (the "
                     "minimiser left the branch, no stable state found beyond) or unstable (an eigenvalue "
                     "crossed zero on it); null when none was found"),
}

# A both-sides record names side s's value of SIDE_KEYS[k] "phi_<s><SUFFIXES[k]>".
SUFFIXES = {"phi_star": "", "phi_star_over_pi": "_over_pi", "phi_error": "_error", "kind": "_kind"}


def side_key(side, key):
    """The both-sides name of one side's ``key`` (a key of SUFFIXES): ('plus', 'phi_error') -> 'phi_plus_error'."""
    if side not in SIDES:
        raise ValueError(f"side must be one of {', '.join(SIDES)}, got {side!r}")
    return f"phi_{side}{SUFFIXES[key]}"


KEYS = dict(SIDE_KEYS)
for _side, _where in zip(SIDES, ("phi > 0", "phi < 0")):
    for _key in SUFFIXES:
        KEYS[side_key(_side, _key)] = (SIDE_KEYS[_key][0], f"{_key} of the {_side} side ({_where})")
del _side, _where, _key


def _number(v):
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def side_record(side, phi, error=None, kind=None):
    """One side's critical twist in SIDE_KEYS' names: phi and error in rad (None or NaN: none),
    kind a name (None when there is no end)."""
    if side not in SIDES:
        raise ValueError(f"side must be one of {', '.join(SIDES)}, got {side!r}")
    phi = _number(phi)
    return {"side": side, "phi_star": phi, "phi_star_over_pi": None if phi is None else phi / math.pi,
            "phi_error": None if phi is None else _number(error),
            "kind": None if phi is None or kind in (None, "", "none") else str(kind)}


def both_sides(records):
    """The both-sides keys (phi_plus, phi_plus_over_pi, ..., phi_minus_kind) from ``records``
    {side: a side_record, or None}; a side missing or None gets null in each of its keys."""
    out = {}
    for side in SIDES:
        record = records.get(side) or side_record(side, None)
        for key in SUFFIXES:
            out[side_key(side, key)] = record[key]
    return out


def json_safe(value):
    """``value`` with every non-finite float (NaN, +-inf) replaced by None, in nested dicts,
    lists and tuples (lists then)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


def markdown_table():
    """The keys as a Markdown table (key, unit, meaning): the README shows it."""
    lines = ["| key | unit | meaning |", "|---|---|---|"]
    for key, (unit, meaning) in KEYS.items():
        lines.append(f"| `{key}` | {unit} | {meaning} |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(markdown_table())
