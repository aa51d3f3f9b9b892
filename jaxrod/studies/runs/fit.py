"""The pipeline of ``jaxrod fit``: measured critical twists read from a CSV file, the scenes they
were measured on, and the weighted least-squares fit of shared parameters
(``jaxrod.studies.design.fit_critical_twists``), written as fit.json."""
from __future__ import annotations

import csv
import math
import os

import numpy as np

from ...validation import parse_angle_text

COLUMNS = ("knot", "N", "D", "L", "side", "phi", "sigma")
RING = "ring"  # a Michell ring (B = 1, radius L / 2 pi) instead of a tabulated knot


def read_measurements(path):
    """The rows of the CSV file ``path`` (header: knot, N, D, L, side, phi, sigma; phi and sigma in
    radians or as '6.5pi'): a list of dicts with typed values. ValueError naming the file, the row and
    the column of anything missing or malformed."""
    if not os.path.isfile(path):
        raise ValueError(f"measurements: no file {path}")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in COLUMNS if c not in (reader.fieldnames or ())]
        if missing:
            raise ValueError(f"measurements: {path} has no column {', '.join(missing)} "
                             f"(the header must name {', '.join(COLUMNS)})")
        rows = []
        for i, row in enumerate(reader, start=2):
            where = f"measurements: {path} line {i}"
            try:
                typed = dict(knot=row["knot"].strip(), N=int(row["N"]), D=float(row["D"]), L=float(row["L"]),
                             side=row["side"].strip(), phi=parse_angle_text(row["phi"], "phi"),
                             sigma=parse_angle_text(row["sigma"], "sigma"))
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{where}: {exc}") from None
            if typed["side"] not in ("plus", "minus"):
                raise ValueError(f"{where}, side: 'plus' or 'minus', got {typed['side']!r}")
            if not typed["sigma"] > 0.0:
                raise ValueError(f"{where}, sigma: must be > 0, got {row['sigma']!r}")
            rows.append(typed)
    if not rows:
        raise ValueError(f"measurements: {path} has no rows")
    return rows


def scene_of(row, nu):
    """The rod a measurement was made on, at the Poisson ratio ``nu`` (the fit's start)."""
    from ...model.scenes import knot, michell_ring

    if row["knot"] == RING:
        return michell_ring(N=row["N"], nu=nu, slenderness=2.0 * math.pi * row["D"] / row["L"])
    return knot(row["knot"], N=row["N"], D=row["D"], L=row["L"], nu=nu)


def fit_file(path, parameters, nu, phi_min, phi_max):
    """Read ``path``, fit ``parameters`` from the scenes at Poisson ratio ``nu``: -> (rows, FitResult)."""
    from ..design import Measurement, fit_critical_twists

    rows = read_measurements(path)
    data = [Measurement(scene_of(r, nu), r["side"], r["phi"], r["sigma"]) for r in rows]
    return rows, fit_critical_twists(data, parameters, phi_min=phi_min, phi_max=phi_max)


def fit_json(rows, fit):
    """fit.json's content: the estimates with standard errors, and each measurement's residual."""
    return {
        "parameters": {name: {"value": float(v), "standard_error": float(e)}
                       for name, v, e in zip(fit.parameters, fit.values, fit.standard_errors)},
        "chi2": fit.chi2, "degrees_of_freedom": len(rows) - len(fit.parameters),
        "converged": fit.converged, "evaluations": fit.iterations, "reason": fit.reason,
        "measurements": [dict(row, residual=float(res), phi_fit=float(row["phi"] + res))
                         for row, res in zip(rows, np.asarray(fit.residuals))],
    }
