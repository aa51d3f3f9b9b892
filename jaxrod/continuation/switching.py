"""Branch switching at a located branch end: relax from the predicted state pushed both ways
along the critical mode (``_switch_branch``) and name the new branch (``_next_branch_name``)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

import jax.numpy as jnp

from ..solve.equilibrium import TopologyChangeError, mode_step, relax
from ..model.geometry import polyline_distance
from ..solve.solvers import ConvergenceError


def _next_branch_name(name):
    """symmetric -> buckled -> buckled2 -> buckled3 ..."""
    if not name.startswith("buckled"):
        return "buckled"
    tail = name[len("buckled"):]
    return f"buckled{int(tail) + 1 if tail.isdigit() else 2}"


# How the stable-only engine picks the branch past an end, named in each instability's ``switch``
# record (with which start won and what the others reached), so the choice is stated.
SWITCH_RULE = ("relaxed from the predicted state pushed +-perturbation along the critical mode and from the "
               "state the corrector jumped to; of the stable states that left the old branch with Lk kept, "
               "the lowest in energy")


def _switch_branch(engine, prev, dq, phi, mode, lost_eq, say):
    """Relax from the predicted state pushed both ways along the critical mode (and from the
    state the corrector itself jumped to, if any); keep stable states away from the old branch
    with the right Lk. Returns (the lowest in energy as an analysed _Step, or None; the choice:
    a dict with the rule (SWITCH_RULE), the start chosen and what each start reached)."""
    scene, closed, jump_tol = engine.scene, engine.closed, engine.opts.jump_tol
    q_pred = prev.q + dq * (phi - prev.phi)
    x_pred = np.asarray(scene.unpack(jnp.asarray(q_pred), phi)[0])
    step = mode_step(scene, mode, float(engine.opts.perturbation))  # resolved: jump_tol unless given
    starts = [("+mode", q_pred + step), ("-mode", q_pred - step)]
    # where the corrector itself goes when left alone (it was stopped early while locating the end)
    starts.append(("jumped", np.asarray(lost_eq.q) if lost_eq is not None else q_pred))
    best, chosen, candidates = None, None, []
    for label, q_start in starts:
        try:
            e = relax(scene, phi, q_start, replace(engine.corrector_options, max_steps=None), previous=prev,
                      nbr=prev.neighbourhood)
        except (ConvergenceError, TopologyChangeError) as exc:
            say(f"  switch from {label}: {type(exc).__name__}: {exc}")
            candidates.append({"start": label, "failed": f"{type(exc).__name__}: {exc}"})
            continue
        moved = polyline_distance(e.x, x_pred, closed)
        s = engine.analysed(e)
        e = s.equilibrium
        lk_ok = (not closed) or abs(e.Lk - (engine.lk0 + phi / (2.0 * math.pi))) <= 1e-6
        say(f"  switch from {label}: E = {e.energy:.8g}, Wr = {e.Wr:.4f}, moved {moved:.3g}, "
            f"{e.stability.n_negative} negative, Lk ok: {lk_ok}")
        kept = bool(moved > jump_tol and e.stability.stable and lk_ok)
        candidates.append({"start": label, "energy": float(e.energy), "Wr": float(e.Wr), "moved": float(moved),
                           "n_negative": int(e.stability.n_negative), "Lk_ok": bool(lk_ok), "kept": kept})
        if not kept:
            continue
        if best is None or e.energy < best.equilibrium.energy:
            best, chosen = s, label
    return best, {"rule": SWITCH_RULE, "chosen": chosen, "candidates": candidates}
