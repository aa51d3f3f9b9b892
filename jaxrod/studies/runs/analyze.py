"""The analysis of a rod from two files, its centreline and an eccentric line drawn on its
surface (CSV, NPY or a study's step file): the summary record and its files (what ``jaxrod
analyze`` runs).

    from jaxrod.studies.runs import AnalyzeOptions, analyze_files
    rod = analyze_files(AnalyzeOptions("results/trefoil/steps/plus_0013.npz"))
    rod.result["Wr"], rod.result["Lk_gauss"]
"""
from __future__ import annotations

import dataclasses
import json
import math
import os


@dataclasses.dataclass(frozen=True)
class AnalyzeOptions:
    """centreline, eccentric: file paths (eccentric None: the centreline's step file holds both);
    closed: closed loops (else open curves); joint_twist: the twist (rad) imposed at the joint
    (None: a step file's phi, else none); n_samples: nodes equally spaced in arc length, >= 4
    (None: as many as centreline points); smoothing_modes: Fourier modes (closed) or spline
    intervals (open) of a least-squares smoothing, >= 1 (None: none)."""

    centreline: str
    eccentric: str | None = None
    closed: bool = True
    joint_twist: float | None = None
    n_samples: int | None = None
    smoothing_modes: int | None = None

    def checked(self):
        """These options, their counts checked (ValueError naming the field)."""
        from ...validation import check_int_at_least

        if self.n_samples is not None:
            check_int_at_least("n_samples", self.n_samples, 4)
        if self.smoothing_modes is not None:
            check_int_at_least("smoothing_modes", self.smoothing_modes, 1)
        return self


@dataclasses.dataclass
class AnalysedRod:
    """``analysis``: the ``jaxrod.measure.analysis.analyze`` result (profiles s, kappa, tau of
    shape (n,), in the files' length unit); ``result``: the summary record (JSON-ready: NaN as
    None); ``symmetry_order`` and ``n_peaks`` of the curvature (None for open curves)."""

    options: AnalyzeOptions
    analysis: object
    result: dict


def json_number(v):
    """float for JSON, None for NaN (strict JSON has no NaN)."""
    v = float(v)
    return v if math.isfinite(v) else None


def analyze_files(options):
    """Loads the two lines of ``options``, analyses them and returns an ``AnalysedRod``. Raises
    ValueError where the eccentric line is not given and the centreline is not a step file, OSError
    where a file cannot be read."""
    from ...measure.analysis import analyze, load_joint_twist, load_polyline

    options = options.checked()
    eccentric = options.eccentric
    if eccentric is None:
        if os.path.splitext(options.centreline)[1].lower() != ".npz":
            raise ValueError(f"{options.centreline}: give the eccentric line too (a second file); only a study's "
                             "step file (steps/*.npz) holds both the centreline and the eccentric line")
        eccentric = options.centreline
    centre = load_polyline(options.centreline, array="x")
    ecc = load_polyline(eccentric, array="eccentric")
    joint = options.joint_twist
    if joint is None and options.closed:  # the twist imposed on the simulated rod whose line this is
        joint = load_joint_twist(eccentric)
    res = analyze(centre, ecc, closed=options.closed, n_samples=options.n_samples,
                  smoothing_modes=options.smoothing_modes, joint_twist=joint)
    return AnalysedRod(options, res, _summary(options, res, eccentric))


def _summary(options, res, eccentric):
    """The summary record of an analysis (printed by --json, written to summary.json)."""
    from ...measure.analysis import count_peaks, symmetry_order

    n, closed = int(res.s.shape[0]), options.closed
    return {
        "Wr": res.Wr,
        "Tw": res.Tw,
        "Lk_frames": res.Lk_frames,
        "Lk_gauss": json_number(res.Lk_exact),
        "Lk_quadrature": json_number(res.Lk_quadrature),
        "Tw_integral": res.Tw_integral,
        "joint_twist": res.joint_twist,
        "joint_jump": json_number(res.joint_jump),
        "length": res.length,
        "symmetry_order": symmetry_order(res.kappa) if closed and n >= 8 else None,
        "n_peaks": count_peaks(res.kappa) if closed and n >= 8 else None,
        "n_samples": n,
        "closed": closed,
        "smoothing_modes": options.smoothing_modes,
        "n_unpaired": int(n - int(res.paired.sum())),
        "warnings": list(res.warnings),
        "centreline": os.path.abspath(options.centreline),
        "eccentric": os.path.abspath(eccentric),
    }


def write_analysis_files(rod, out):
    """Writes profiles.csv, summary.json and profiles.png (kappa L and tau L against s/L) into the
    folder ``out``; returns their names."""
    from ...io import plotting
    from ...measure.analysis import write_profiles_csv

    res, closed, L = rod.analysis, rod.options.closed, rod.analysis.length
    write_profiles_csv(res, os.path.join(out, "profiles.csv"))
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(rod.result, f, indent=2)
    lk = "" if not closed else f", Lk = {res.Lk_exact:.0f}" if math.isfinite(res.Lk_exact) else \
        f", Lk = {res.Lk_frames:.4f}"
    plotting.plot_profiles(
        res.s / L, [(res.kappa * L, res.tau * L)], [os.path.basename(rod.options.centreline)],
        path=os.path.join(out, "profiles.png"),
        title=f"Wr = {res.Wr:.4f}, Tw = {res.Tw:.4f}{lk}",
    )
    return ["profiles.csv", "summary.json", "profiles.png"]
