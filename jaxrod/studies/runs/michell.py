"""Michell's ring: the critical twist of a closed, initially circular rod, against Michell's
analytic 2 pi sqrt(3)(1 + nu), with its JSON record and its files (what ``jaxrod michell`` runs).

    from jaxrod.studies.runs import MichellOptions, run_michell, write_michell_files
    run = run_michell(MichellOptions(N=128, nu=0.5))
    run.result["phi_star"], run.result["rel_error"]
"""
from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
import time

# A ring of fewer nodes does not buckle within twice Michell's twist.
MICHELL_MIN_NODES = 8


@dataclasses.dataclass(frozen=True)
class MichellOptions:
    """N nodes (at least MICHELL_MIN_NODES); Poisson ratio nu in (-1, 0.5] (B/C = 1 + nu);
    slenderness D/R, the rod diameter over the ring radius; tol, the accuracy of phi* in rad."""

    N: int = 128
    nu: float = 0.5
    slenderness: float = 0.01
    tol: float = 1e-6 * math.pi

    def checked(self):
        """These options, checked (ValueError naming the field), nu as a float."""
        from ...validation import check_int_at_least, check_poisson_ratio, check_positive

        check_int_at_least("N", self.N, MICHELL_MIN_NODES)
        nu = check_poisson_ratio("nu", self.nu)
        check_positive("slenderness", self.slenderness)
        check_positive("tol", self.tol)
        return dataclasses.replace(self, nu=nu)


@dataclasses.dataclass
class MichellRun:
    """A solved ring: its scene, the CriticalPoint ``critical`` (phi in rad, its eigenvalue scan),
    Michell's ``analytic`` phi* (rad), the wall time ``seconds`` and ``result``, the JSON record
    (``michell_json``)."""

    options: MichellOptions
    scene: object
    critical: object
    analytic: float
    seconds: float
    result: dict


def michell_scene(options):
    """(scene, analytic phi* in rad) of the ring of ``options``."""
    from ...model.scenes import michell_critical_twist, michell_ring

    return michell_ring(N=options.N, nu=options.nu, slenderness=options.slenderness), michell_critical_twist(options.nu)


def run_michell(options, observer=None):
    """The ring's critical twist, scanned from 0 up to twice Michell's value in steps of a tenth of
    it and refined to ``options.tol``; ``observer`` (``jaxrod.continuation.Observer``) sees the
    scan. Raises NoCrossingError where none is found. Returns a ``MichellRun``."""
    from ... import continuation

    options = options.checked()
    t0 = time.perf_counter()
    scene, analytic = michell_scene(options)
    cp = continuation.critical_twist(scene, 0.0, 2.0 * analytic,
                                     continuation.ContinuationOptions(step=analytic / 10.0, tol=options.tol),
                                     observer=observer)
    seconds = time.perf_counter() - t0
    return MichellRun(options, scene, cp, analytic, seconds,
                      michell_json(cp, analytic, options.N, options.nu, seconds))


def michell_json(cp, analytic, N, nu, seconds):
    """michell's JSON (printed by --json, written to michell.json): the critical twist under
    jaxrod.io.schema's one-side keys, and the comparison with Michell's value."""
    from ...io import schema

    result = schema.side_record("plus", cp.phi, cp.phi_error, "unstable")  # an eigenvalue pair crosses zero
    result.update({
        "phi_star_analytic": analytic,
        "rel_error": (cp.phi - analytic) / analytic,
        "N": N,
        "nu": nu,
        "seconds": seconds,
        "phi_error_bound": cp.phi_error,  # the former name of phi_error
        "multiplicity": cp.multiplicity,
        "dlambda_dphi": cp.dlambda_dphi,
        "hessian_evaluations": cp.hessian_evaluations,
    })
    return schema.json_safe(result)


def write_michell_files(run, out):
    """Writes michell.json, scan.csv (phi, phi/pi, the negative count and the lowest eigenvalues of
    each scanned state), eigenvalues.png and critical_mode.png into the folder ``out``; returns
    their names."""
    from ...io import plotting

    cp, analytic, N, nu = run.critical, run.analytic, run.options.N, run.options.nu
    with open(os.path.join(out, "michell.json"), "w") as f:
        json.dump(run.result, f, indent=2)
    with open(os.path.join(out, "scan.csv"), "w", newline="") as f:
        w = csv.writer(f)
        k = len(cp.scan[0][2])
        w.writerow(["phi", "phi_over_pi", "n_negative"] + [f"lambda_{j}" for j in range(k)])
        for phi, n_neg, lam in cp.scan:
            w.writerow([phi, phi / math.pi, n_neg] + [float(v) for v in lam])
    plotting.plot_eigenvalue_scan(
        cp.scan, cp, os.path.join(out, "eigenvalues.png"),
        title=f"Michell ring, N = {N}, nu = {nu}", analytic=(analytic, "analytic 2 pi sqrt(3)(1 + nu)"),
    )
    mode_q = run.scene.from_scaled(cp.mode)
    x_mode, _ = run.scene.unpack(mode_q, 0.0)
    plotting.plot_mode(
        cp.equilibrium.x, x_mode, os.path.join(out, "critical_mode.png"),
        title=f"Critical mode at phi* = {cp.phi / math.pi:.5f} pi",
    )
    return ["michell.json", "scan.csv", "eigenvalues.png", "critical_mode.png"]
