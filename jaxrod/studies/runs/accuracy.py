"""A knot's two critical twists converged in N (the accuracy mode of ``jaxrod trefoil`` and
``jaxrod knot``): each side's first branch end at N, 2N-1, 4N-3, ... (each level started from the
previous one) until Richardson's extrapolation, with its order measured, is accurate enough;
written to the folder out: levels/ as they are found, convergence.csv, convergence.png.

    from jaxrod.studies.runs import KnotStudyOptions, run_accuracy, study_scene
    options = KnotStudyOptions(N=61, accuracy=0.01 * math.pi, out="results/accuracy")
    run = run_accuracy(study_scene(options), options)
    run.convergence["plus"].phi_star, run.convergence["plus"].error      # rad
"""
from __future__ import annotations

import csv
import dataclasses
import math
import os
import shutil
import time

from .trefoil import critical_json


@dataclasses.dataclass
class AccuracyRun:
    """``convergence``: {side: SideConvergence} (``converged_critical_twists``); ``seconds``, the
    wall time; ``summary``, the JSON record (``critical_json``); ``reached``: both sides within
    the accuracy asked."""

    convergence: dict
    seconds: float
    summary: dict

    @property
    def reached(self):
        return all(r.reached for r in self.convergence.values())


def accuracy_levels(options):
    """The node counts N, 2N-1, 4N-3, ... up to options.N_max that the accuracy mode may use."""
    from ..accuracy import resolution_levels

    return resolution_levels(options.N, options.N_max)


def run_accuracy(scene, options, progress=None):
    """Both sides' first branch ends of ``scene`` (built at options.N) converged in N to
    options.accuracy (rad); with options.fresh the levels on file are dropped first. Writes
    convergence.csv and (with figures) convergence.png into options.out. Returns an ``AccuracyRun``."""
    from ..accuracy import converged_critical_twists

    o = options
    if o.fresh:
        shutil.rmtree(os.path.join(o.out, "levels"), ignore_errors=True)
    t0 = time.perf_counter()
    result = converged_critical_twists(scene, o.accuracy, N_max=o.N_max, span=max(-o.phi_min, o.phi_max),
                                       step=o.step, progress=progress, parallel=not o.serial, out=o.out)
    seconds = time.perf_counter() - t0
    write_convergence_csv(result, os.path.join(o.out, "convergence.csv"))
    if o.figures:
        from ...io.plotting import plot_resolution_convergence

        path = os.path.join(o.out, "convergence.png")
        plot_resolution_convergence(result, path, title=f"{scene.name}, D/L = {o.D / o.L:.4f}: "
                                                        f"critical twists converged in N")
        if progress is not None:
            progress(f"wrote {path}")
    summary = critical_json({"D": o.D, "L": o.L, "nu": o.nu, "contact_stiffness": o.contact_stiffness,
                             "accuracy": o.accuracy, "seconds": seconds, "out": o.out}, convergence=result)
    return AccuracyRun(result, seconds, summary)


def write_convergence_csv(convergence, path):
    """convergence.csv: a row per side and level (N, phi* in rad and /pi, its error, kind, seconds)."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["side", "N", "phi_star", "phi_star_over_pi", "phi_error", "kind", "seconds"])
        for side, r in convergence.items():
            for lv in r.levels:
                w.writerow([side, lv.N, repr(lv.phi_star), repr(lv.phi_star / math.pi), repr(lv.phi_error), lv.kind,
                            f"{lv.seconds:.3f}"])
