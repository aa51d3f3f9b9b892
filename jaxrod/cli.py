"""Command line: ``jaxrod michell ...``, ``jaxrod trefoil ...``, ``jaxrod analyze CENTRELINE ECCENTRIC ...``.

Progress goes to stderr; results to stdout (``--json``: one JSON object); figures and data
(PNG, CSV, JSON) into ``--out DIR``. Bad input exits with status 2, a computation that fails
(no critical twist in range, no equilibrium) with status 1, Ctrl-C with 130: each with one line
on stderr that says what to change (or, for an interrupted study, that it resumes).
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys
import time

__all__ = ["main"]


def _angle(text):
    """Parse an angle in radians; accepts '12pi', '-8*pi', '3.5pi', 'pi', or a plain number."""
    s = text.strip().lower().replace(" ", "")
    try:
        if s.endswith("pi"):
            head = s[:-2].rstrip("*")
            factor = 1.0 if head in ("", "+") else -1.0 if head == "-" else float(head)
            return factor * math.pi
        return float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an angle: {text!r} (use e.g. 12pi or 3.7)") from None


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, status 2
        self.exit(2, f"jaxrod: error: {message}\n")


def _build_parser():
    p = _Parser(prog="jaxrod", description="Equilibria and buckling of twisted elastic rods.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    m = sub.add_parser("michell", help="critical twist of Michell's ring, compared with 2 pi sqrt(3)(1+nu)")
    m.add_argument("--N", type=int, default=128, help="number of nodes (default 128)")
    m.add_argument("--nu", type=float, default=0.5, help="Poisson ratio, B/C = 1 + nu (default 0.5)")
    m.add_argument("--slenderness", type=float, default=0.01, help="D/R (default 0.01)")
    m.add_argument("--tol", type=_angle, default=1e-6 * math.pi, help="accuracy of phi* (default 1e-6pi)")
    m.add_argument("--json", action="store_true", help="print one JSON object")
    m.add_argument("--out", default=None, help="folder for figures and data")
    m.add_argument("--quiet", action="store_true", help="no progress on stderr")
    m.add_argument("--no-cache", action="store_true",
                   help="do not keep compiled code in ~/.cache/jaxrod (later runs then compile again)")
    a = sub.add_parser(
        "analyze",
        help="frames, curvature/twist profiles and Wr, Tw, Lk of a rod from two polylines (CSV or NPY)",
        description="Analyse a rod from its centreline and an eccentric line drawn on its surface "
        "(files: CSV with an x,y,z header or three bare columns, or .npy arrays of shape (N, 3)).",
    )
    a.add_argument("centreline", help="centreline points (.csv or .npy)")
    a.add_argument("eccentric", help="eccentric-line points (.csv or .npy)")
    a.add_argument("--open", action="store_true", help="open curves (default: closed loops)")
    a.add_argument("--n-samples", type=int, default=None,
                   help="number of nodes, equally spaced in arc length (default: as many as centreline points)")
    a.add_argument("--smoothing-modes", type=int, default=None,
                   help="least-squares smoothing with K modes (Fourier, closed) or K spline intervals (open)")
    a.add_argument("--out", default=None, help="folder for profiles.csv, summary.json, profiles.png")
    a.add_argument("--json", action="store_true", help="print one JSON object")
    a.add_argument("--quiet", action="store_true", help="no progress on stderr")
    t = sub.add_parser("trefoil", help="twisted trefoil knot: both critical twists, branches beyond, figures")
    t.add_argument("--D", type=float, default=8.0, help="rod diameter (default 8, mm)")
    t.add_argument("--L", type=float, default=292.0, help="rod length (default 292, mm)")
    t.add_argument("--N", type=int, default=121, help="number of nodes (default 121)")
    t.add_argument("--E", type=float, default=0.474, help="Young's modulus (default 0.474, MPa = N/mm^2)")
    t.add_argument("--nu", type=float, default=0.5, help="Poisson ratio, B/C = 1 + nu (default 0.5)")
    t.add_argument("--chirality", choices=("right", "left"), default="right", help="knot handedness (default right)")
    t.add_argument("--contact-stiffness", type=float, default=None,
                   help="contact penalty kappa_c in units of B/D^3 (default: the scene's, 100)")
    t.add_argument("--phi-min", type=_angle, default=-12.0 * math.pi, help="lowest twist (default -12pi)")
    t.add_argument("--phi-max", type=_angle, default=14.0 * math.pi, help="highest twist (default 14pi)")
    t.add_argument("--step", type=_angle, default=0.5 * math.pi, help="largest continuation step (default 0.5pi)")
    t.add_argument("--tol", type=_angle, default=2e-4 * math.pi, help="accuracy of the critical twists (default 2e-4pi)")
    t.add_argument("--out", default="results/trefoil", help="output folder (default results/trefoil)")
    t.add_argument("--fresh", action="store_true", help="start over even if --out holds an interrupted run")
    t.add_argument("--serial", action="store_true",
                   help="follow the two directions one after the other (default: both at once, two threads)")
    t.add_argument("--no-figures", action="store_true", help="data only")
    t.add_argument("--json", action="store_true", help="print one JSON summary object")
    t.add_argument("--quiet", action="store_true", help="no progress on stderr")
    t.add_argument("--no-cache", action="store_true", help="do not keep compiled code in ~/.cache/jaxrod")
    return p


def _enable_compilation_cache(args):
    """Keep XLA's compiled code between runs (first run ~30 s, later runs a few s), unless the
    user chose a cache already (JAX_COMPILATION_CACHE_DIR) or passed --no-cache."""
    if getattr(args, "no_cache", False) or os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        return
    import jax

    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    path = os.path.join(base, "jaxrod", "xla")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return  # read-only home: run without a cache
    jax.config.update("jax_compilation_cache_dir", path)
    # Every compilation, also the many small ones under the default 1 s threshold.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)


def _michell(args):
    import matplotlib

    matplotlib.use("Agg")  # files only, no display needed
    from . import plotting
    from .continuation import critical_twist
    from .validation import check_int_at_least, check_poisson_ratio, check_positive
    from .scenes import michell_critical_twist, michell_ring

    check_int_at_least("N", args.N, 4)
    nu = check_poisson_ratio("nu", args.nu)
    check_positive("slenderness", args.slenderness)
    say = (lambda s: None) if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    t0 = time.perf_counter()
    scene = michell_ring(args.N, nu=nu, slenderness=args.slenderness)
    analytic = michell_critical_twist(nu)
    say(f"Michell ring: N = {args.N}, nu = {nu}, analytic phi* = {analytic / math.pi:.6f} pi")
    cp = critical_twist(
        scene, 0.0, 2.0 * analytic, step=analytic / 10.0, tol=args.tol, progress=say
    )
    seconds = time.perf_counter() - t0
    rel = (cp.phi - analytic) / analytic
    result = {
        "phi_star": cp.phi,
        "phi_star_analytic": analytic,
        "rel_error": rel,
        "N": args.N,
        "nu": nu,
        "seconds": seconds,
        "phi_error_bound": cp.phi_error,
        "multiplicity": cp.multiplicity,
        "dlambda_dphi": cp.dlambda_dphi,
        "hessian_evaluations": cp.hessian_evaluations,
    }
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        with open(os.path.join(args.out, "michell.json"), "w") as f:
            json.dump(result, f, indent=2)
        with open(os.path.join(args.out, "scan.csv"), "w", newline="") as f:
            w = csv.writer(f)
            k = len(cp.scan[0][2])
            w.writerow(["phi", "phi_over_pi", "n_negative"] + [f"lambda_{j}" for j in range(k)])
            for phi, n_neg, lam in cp.scan:
                w.writerow([phi, phi / math.pi, n_neg] + [float(v) for v in lam])
        plotting.plot_eigenvalue_scan(
            cp.scan, cp, os.path.join(args.out, "eigenvalues.png"),
            title=f"Michell ring, N = {args.N}, nu = {nu}",
        )
        mode_q = scene.from_scaled(cp.mode)
        x_mode, _ = scene.unpack(mode_q, 0.0)
        plotting.plot_mode(
            cp.equilibrium.x, x_mode, os.path.join(args.out, "critical_mode.png"),
            title=f"Critical mode at phi* = {cp.phi / math.pi:.5f} pi",
        )
        say(f"wrote {args.out}/michell.json, scan.csv, eigenvalues.png, critical_mode.png")
    if args.json:
        print(json.dumps(result))
    else:
        print(f"phi*          = {cp.phi:.12f} rad = {cp.phi / math.pi:.10f} pi  (+- {cp.phi_error:.1e})")
        print(f"analytic      = {analytic:.12f} rad = {analytic / math.pi:.10f} pi  (2 pi sqrt(3) (1+nu))")
        print(f"rel. error    = {rel:.3e}")
        print(f"time          = {seconds:.2f} s ({cp.hessian_evaluations} Hessian evaluations in the refinement)")
    return 0


def _json_number(v):
    """float for JSON, None for NaN (strict JSON has no NaN)."""
    v = float(v)
    return v if math.isfinite(v) else None


def _analyze(args):
    import matplotlib

    matplotlib.use("Agg")  # files only, no display needed
    from . import plotting
    from .analysis import analyze, count_peaks, load_polyline, symmetry_order, write_profiles_csv

    say = (lambda s: None) if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    centre = load_polyline(args.centreline)
    ecc = load_polyline(args.eccentric)
    closed = not args.open
    res = analyze(centre, ecc, closed=closed, n_samples=args.n_samples, smoothing_modes=args.smoothing_modes)
    L = res.length
    n = int(res.s.shape[0])
    order = symmetry_order(res.kappa) if closed and n >= 8 else None
    peaks = count_peaks(res.kappa) if closed and n >= 8 else None
    result = {
        "Wr": res.Wr,
        "Tw": res.Tw,
        "Lk_frames": res.Lk_frames,
        "Lk_gauss": _json_number(res.Lk_exact),
        "Lk_quadrature": _json_number(res.Lk_quadrature),
        "Tw_integral": res.Tw_integral,
        "length": L,
        "symmetry_order": order,
        "n_peaks": peaks,
        "n_samples": n,
        "closed": closed,
        "smoothing_modes": args.smoothing_modes,
        "n_unpaired": int(n - int(res.paired.sum())),
        "centreline": os.path.abspath(args.centreline),
        "eccentric": os.path.abspath(args.eccentric),
    }
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        write_profiles_csv(res, os.path.join(args.out, "profiles.csv"))
        with open(os.path.join(args.out, "summary.json"), "w") as f:
            json.dump(result, f, indent=2)
        lk = "" if not closed else f", Lk = {res.Lk_exact:.0f}"
        plotting.plot_profiles(
            res.s / L, [(res.kappa * L, res.tau * L)], [os.path.basename(args.centreline)],
            path=os.path.join(args.out, "profiles.png"),
            title=f"Wr = {res.Wr:.4f}, Tw = {res.Tw:.4f}{lk}",
        )
        say(f"wrote {args.out}/profiles.csv, summary.json, profiles.png")
    if args.json:
        print(json.dumps(result))
    else:
        fmt = lambda v: "n/a (open curve)" if v is None or not math.isfinite(v) else f"{v:.10f}"  # noqa: E731
        print(f"Wr            = {res.Wr:.10f}")
        print(f"Tw            = {res.Tw:.10f}   (integral of tau: {res.Tw_integral:.10f})")
        print(f"Lk (frames)   = {res.Lk_frames:.10f}   (Wr + Tw)")
        print(f"Lk (Gauss)    = {fmt(res.Lk_exact)}   (exact polygon linking number)")
        print(f"Lk (quadr.)   = {fmt(res.Lk_quadrature)}   (midpoint Gauss quadrature)")
        print(f"length        = {L:.10g}   ({n} nodes)")
        if closed:
            print(f"kappa profile : symmetry order {order}, {peaks} peak(s)")
        if result["n_unpaired"]:
            print(f"warning       : {result['n_unpaired']} node(s) whose normal plane misses the eccentric line")
    return 0


def _trefoil(args):
    import matplotlib

    matplotlib.use("Agg")
    from .validation import check_int_at_least
    from .scenes import DEFAULT_CONTACT_STIFFNESS, trefoil
    from .study import figures, study_summary, twist_study

    check_int_at_least("N", args.N, 24)
    say = (lambda s: None) if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    stiffness = DEFAULT_CONTACT_STIFFNESS if args.contact_stiffness is None else args.contact_stiffness
    scene = trefoil(args.D, args.L, args.N, E=args.E, nu=args.nu, chirality=args.chirality,
                    contact_stiffness=stiffness)
    say(f"{scene.name}: D = {args.D}, L = {args.L}, N = {args.N}, nu = {args.nu}, kappa_c = {stiffness}; "
        f"phi from {args.phi_min / math.pi:+.3f} pi to {args.phi_max / math.pi:+.3f} pi; writing {args.out}/")
    result = twist_study(scene, args.phi_min, args.phi_max, step=args.step, out=args.out, tol=args.tol,
                         progress=say, resume=not args.fresh, parallel=not args.serial)
    summary = study_summary(result)
    summary.update({"D": args.D, "L": args.L, "N": args.N, "nu": args.nu, "chirality": args.chirality,
                    "contact_stiffness": stiffness, "out": args.out})
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    if not args.no_figures:
        for path in figures(args.out, title=f"{scene.name}, D/L = {args.D / args.L:.4f}, N = {args.N}"):
            say(f"wrote {path}")
    if args.json:
        print(json.dumps(summary))
    else:
        for key in ("phi_plus", "phi_minus"):
            v = summary[key]
            print(f"{key:10s} = " + ("none in range" if v is None else f"{v:+.6f} rad = {v / math.pi:+.5f} pi"))
        total = summary.get("seconds_total")
        resumed = f" ({total:.1f} s with the interrupted runs)" if total and total > summary["seconds"] + 0.05 else ""
        print(f"tightening side: {summary.get('tightening_side')}; time {summary['seconds']:.1f} s{resumed}; "
              f"data in {args.out}/")
    return 0


# Options whose value is an angle such as -12pi: argparse would read a leading '-' as an option.
_ANGLE_OPTIONS = ("--phi-min", "--phi-max", "--step", "--tol")


def _join_angle_values(argv):
    out, i = [], 0
    while i < len(argv):
        if argv[i] in _ANGLE_OPTIONS and i + 1 < len(argv):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def main(argv=None):
    argv = _join_angle_values(list(sys.argv[1:] if argv is None else argv))
    args = _build_parser().parse_args(argv)
    try:
        import jaxrod  # noqa: F401  (float64, BLAS threads)

        _enable_compilation_cache(args)

        if args.command == "michell":
            return _michell(args)
        if args.command == "analyze":
            return _analyze(args)
        if args.command == "trefoil":
            return _trefoil(args)
    except ValueError as exc:
        print(f"jaxrod: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # missing or unreadable file, unwritable --out
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        print(f"jaxrod: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        hint = f"; the same command resumes from what is in {args.out}/" if args.command == "trefoil" else ""
        print(f"jaxrod: interrupted{hint}", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 -- a failed computation: one line, what to change
        from .continuation import NoCrossingError
        from .solvers import ConvergenceError

        if isinstance(exc, NoCrossingError):
            advice = ("no critical twist up to twice Michell's value: raise --N (a ring of a few nodes "
                      "does not buckle)" if args.command == "michell" else
                      "no critical twist in the range: widen it (--phi-min / --phi-max) or raise --N")
        elif isinstance(exc, ConvergenceError):
            advice = ("no equilibrium found: raise --N (for a knot, edges no longer than the diameter: "
                      "N >= L/D), or loosen the knot (larger --L/--D)")
        else:
            raise
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if len(detail) > 160:
            detail = detail[:157] + "..."
        print(f"jaxrod: error: {advice} ({detail})", file=sys.stderr)
        return 1
    return 1


if __name__ == "__main__":
    sys.exit(main())
