"""What a twist study's critical.json says about its two sides: the first instability of each
(``summarise_critical``: bracketed by the study, or located exactly by the diagram), which side
tightens the knot (``tightening_side``), and a short summary of a study (``study_summary``)."""
from __future__ import annotations

import math

import numpy as np

from ..continuation.end_check import onset_events

__all__ = ["summarise_critical", "SIDES_EQUAL_RTOL", "tightening_side", "study_summary"]


def summarise_critical(critical, table=None):
    """phi_plus / phi_minus: first instability met at phi > 0 / phi < 0 (jaxrod's sign of phi,
    radians). The tightening side is told by behaviour along the symmetric branch: the number of
    segment pairs in contact grows on the tightening side and falls on the opening side."""
    for direction, key in (("plus", "phi_plus"), ("minus", "phi_minus")):
        first = [c for c in critical["instabilities"] if c["direction"] == direction]
        critical[key] = first[0]["phi"] if first else None
        critical[key + "_error"] = first[0]["phi_error"] if first else None
        critical[key + "_dlambda_dphi"] = first[0]["dlambda_dphi"] if first else None
        critical[key + "_mode_file"] = first[0].get("mode_file") if first else None
        # a located end replaces the bracket's estimate (kept as ``<key>_bracketed``) only where it lies in
        # the bracket and is the study's critical mode (files without that check count as verified)
        index = critical["instabilities"].index(first[0]) if first else None
        ours = [ev for ev in critical.get("events", []) if ev.get("instability") == index]
        located = [ev for ev in ours if ev.get("located") and ev.get("within_bracket") is not False
                   and ev.get("confirmed", True)]
        if first:
            critical[key + "_events"] = onset_events(first[0], ours[0] if ours else None)
        if located:
            ev = located[0]
            critical[key + "_bracketed"] = critical[key]
            critical[key + "_bracketed_error"] = critical[key + "_error"]
            critical[key] = ev["phi"]
            critical[key + "_error"] = None
            critical[key + "_located"] = {name: ev.get(name) for name in ("kind", "critical_eigenvalue", "residual",
                                                                       "iterations", "state_file")}
    if table is None or "radius_of_gyration" not in table:
        return
    rg, phi, br, cc = table["radius_of_gyration"], table["phi"], table["branch"], table["contact_count"]
    sym = np.char.startswith(br.astype(str), "symmetric")
    at0 = sym & (phi == 0.0)
    trend = {}
    for direction, sgn in (("plus", 1.0), ("minus", -1.0)):
        sel = sym & (np.sign(phi) == sgn)
        if np.any(sel) and np.any(at0):
            i, i0 = np.argmax(np.abs(phi) * sel), np.argmax(at0)
            trend[direction] = {"contact_count": float(cc[i] - cc[i0]), "radius_of_gyration": float(rg[i] - rg[i0]),
                                "phi_last_symmetric": float(phi[i])}
    if len(trend) == 2:
        tight = tightening_side({d: (t["contact_count"], t["radius_of_gyration"]) for d, t in trend.items()},
                                scale=float(rg[np.argmax(at0)]))
        critical["symmetric_branch_change"] = trend
        if tight == "equal":
            # mirror-image sides: a label decided by round-off would mean nothing
            critical["tightening_side"] = "equal"
            critical["phi_tightening"] = critical["phi_opening"] = None
            return
        critical["tightening_side"] = "phi>0" if tight == "plus" else "phi<0"
        critical["phi_tightening"] = critical["phi_plus" if tight == "plus" else "phi_minus"]
        critical["phi_opening"] = critical["phi_minus" if tight == "plus" else "phi_plus"]


# Two sides whose radius-of-gyration changes differ by less than this fraction of the radius of
# gyration (with equal contact counts) are the same within the solver's accuracy.
SIDES_EQUAL_RTOL = 1e-6


def tightening_side(changes, scale, rtol=SIDES_EQUAL_RTOL):
    """Which side tightens (packs the strands together): ``changes`` {'plus': (contact pairs gained,
    radius of gyration change), 'minus': (...)}, judged by contacts gained, then radius of
    gyration lost; ``scale`` the length the radius difference is judged by. Returns 'plus',
    'minus', or 'equal' when the contact counts agree and the radii differ by at most rtol * scale."""
    (cc_plus, rg_plus), (cc_minus, rg_minus) = changes["plus"], changes["minus"]
    if cc_plus == cc_minus and abs(rg_plus - rg_minus) <= rtol * abs(scale):
        return "equal"
    return "plus" if (cc_plus, -rg_plus) > (cc_minus, -rg_minus) else "minus"


def study_summary(result):
    """A small JSON-able summary of a study: critical twists (rad and /pi), sides, time."""
    c = result.critical
    s = {key: c.get(key) for key in ("phi_plus", "phi_minus", "phi_plus_error", "phi_minus_error",
                                       "tightening_side", "phi_tightening", "phi_opening", "phi_plus_located",
                                       "phi_minus_located", "phi_plus_bracketed", "phi_minus_bracketed")}
    for key in ("phi_plus", "phi_minus", "phi_tightening", "phi_opening"):
        s[key + "_over_pi"] = None if c.get(key) is None else c[key] / math.pi
    s["seconds"] = result.seconds
    s["seconds_total"] = result.seconds_total  # this run and the interrupted ones before it
    s["steps"] = int(len(result.table.get("phi", [])))
    s["corrector_iterations"] = corrector_iterations(result.table)
    return s


def corrector_iterations(table):
    """{direction: {"points", "iterations", "per_point"}}: the corrector's iterations over the
    accepted points of each direction's stable path (branch.csv's ``iterations`` column; the
    trials that were refused, and the unstable branches' rows, are not counted)."""
    if "iterations" not in table or "direction" not in table:
        return {}
    counts = {}
    branches = table.get("branch", [""] * len(table["direction"]))
    for branch, direction, iterations in zip(branches, table["direction"], table["iterations"]):
        if str(branch).startswith("unstable") or math.isnan(float(iterations)):
            continue
        points, total = counts.get(str(direction), (0, 0))
        counts[str(direction)] = (points + 1, total + int(iterations))
    return {d: {"points": p, "iterations": t, "per_point": round(t / p, 2)} for d, (p, t) in sorted(counts.items())}
