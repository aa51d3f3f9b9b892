"""``jaxrod trefoil`` (and ``jaxrod knot``, the same study of another knot): the twist study of a
knot, or with --accuracy its critical twists converged in N."""
from __future__ import annotations

import json
import math

from .common import ANGLES, NO_CACHE_HELP, Progress, add_quiet_and_cache, output_folder, parse_angle

NAME = "trefoil"

# The knot factories' default E (jaxrod.model.scenes.PAPER_YOUNG_MODULUS; a test checks that they agree),
# written here so that `jaxrod --help` reads no scene module.
PAPER_YOUNG_MODULUS = 0.474

# trefoil / knot: --N when not given (the twist study; with --accuracy the coarsest level is the
# larger of ACCURACY_NODES and L/D).
STUDY_NODES = 121
ACCURACY_NODES = 61

HELP = f"""\
The twisted trefoil knot of the seed paper: relax a trefoil of rod diameter D and length L at
zero twist, then follow its stable equilibria as the joint is twisted up to --phi-max and down
to --phi-min; where a branch ends (buckling), locate the critical twist, switch to the buckled
branch and go on. Then the whole diagram: each branch end located exactly on the extended system
(a fold or a branch point) and the unstable branch beyond it (--stable-only skips this). Lengths in
mm (any unit, if D and L share it), E in MPa (N/mm^2).
{ANGLES}

Writes into --out as it goes: branch.csv (a row per step, then the unstable branches' rows),
steps/*.npz, critical.json (phi_plus, phi_minus in radians; events: each located end), summary.json
and figures (bifurcation.png, branch_ends.png, ...). An interrupted run (Ctrl-C, kill) resumes
when the same command is given again, and ends with the same files as an uninterrupted run.

examples:
  jaxrod trefoil --D 8 --L 292 --N 121 --phi-min -12pi --phi-max 14pi --out results/trefoil
  jaxrod trefoil --N 61 --phi-min -0.5pi --phi-max 7.5pi --out results/quick
"""


def add_parser(sub, formatter_class):
    """Adds the trefoil command's parser to the subparsers ``sub``."""
    t = sub.add_parser(NAME, help="twisted trefoil knot: both critical twists, branches beyond, figures",
                       description=HELP, formatter_class=formatter_class)
    t.add_argument("--chirality", choices=("right", "left"), default="right", help="knot handedness (default right)")
    add_study_arguments(t, "results/trefoil", "at least 16.372 D")


def add_study_arguments(t, default_out, length_rule):
    """The options that the trefoil and knot twist studies share."""
    t.add_argument("--D", type=float, default=8.0, help="rod diameter (default 8, mm)")
    t.add_argument("--L", type=float, default=292.0, help=f"rod length, {length_rule} (default 292, mm)")
    t.add_argument("--N", type=int, default=None,
                   help=f"number of nodes, at least 24 and L/D (default {STUDY_NODES}; with --accuracy the coarsest "
                        f"level, default: the larger of {ACCURACY_NODES} and L/D)")
    t.add_argument("--E", type=float, default=PAPER_YOUNG_MODULUS,
                   help=f"Young's modulus (default {PAPER_YOUNG_MODULUS:g}, the seed paper's elastomer, as in the API; "
                        "MPa = N/mm^2)")
    t.add_argument("--nu", type=float, default=0.5, help="Poisson ratio in (-1, 0.5], B/C = 1 + nu (default 0.5)")
    t.add_argument("--contact-stiffness", type=float, default=None,
                   help="contact penalty kappa_c in units of B/D^3 (default: the scene's, 100)")
    t.add_argument("--phi-min", type=parse_angle, default=-12.0 * math.pi, help="lowest twist, < 0 (default -12pi)")
    t.add_argument("--phi-max", type=parse_angle, default=14.0 * math.pi, help="highest twist, > 0 (default 14pi)")
    t.add_argument("--step", type=parse_angle, default=0.5 * math.pi, help="largest continuation step (default 0.5pi)")
    t.add_argument("--tol", type=parse_angle, default=2e-4 * math.pi,
                   help="width to which the study brackets a branch end that is not then located exactly on "
                        "its extended system (a fold or branch point is bracketed to 0.02pi and then located to "
                        "roundoff; with --stable-only every end to this; default 2e-4pi)")
    t.add_argument("--accuracy", type=parse_angle, default=None,
                   help="instead of the twist study: both critical twists converged in N to this accuracy "
                        "(e.g. 0.01pi): N, 2N-1, 4N-3, ... each started from the previous one, extrapolated "
                        "(Richardson, order measured) until the error estimate is below it")
    t.add_argument("--no-extrapolation", action="store_true",
                   help="skip the rough error estimate of the study's critical twists (each end found again at "
                        "N' = (N+1)/2 from the study's state, then Richardson; a few seconds)")
    t.add_argument("--N-max", type=int, default=481,
                   help="with --accuracy: the finest level allowed (default 481; dense linear algebra, "
                        "minutes a side there)")
    t.add_argument("--out", default=default_out, help=f"output folder (default {default_out})")
    t.add_argument("--fresh", action="store_true", help="start over even if --out holds an interrupted run")
    t.add_argument("--serial", action="store_true",
                   help="follow the two directions one after the other (default: both at once, two threads)")
    t.add_argument("--no-figures", action="store_true", help="data only")
    t.add_argument("--stable-only", action="store_true",
                   help="stable branches only: no exact location of the branch ends (extended system), no unstable "
                        "branches beyond them")
    t.add_argument("--vtk", action="store_true",
                   help="also write every step as a VTK polyline file (vtk/*.vtk, for ParaView)")
    t.add_argument("--json", action="store_true", help="print one JSON summary object (the critical twists' keys: "
                                                       "python -m jaxrod.io.schema, and the README)")
    add_quiet_and_cache(t, NO_CACHE_HELP)


def _checked_knot(args):
    """The named knot of a trefoil / knot command (None: --curve), its length checked against the
    knot's ideal ropelength; ValueError naming the flags."""
    from ..model.scenes import IDEAL_ROPELENGTH

    knot_name = "3_1" if args.command == "trefoil" else args.name
    if args.command == "knot" and (knot_name is None) == (args.curve is None):
        raise ValueError("give a knot (3_1, 4_1, 5_1 or 5_2) or --curve FILE" +
                         (", not both" if knot_name is not None else ""))
    L_over_D = args.L / args.D
    if knot_name is not None and L_over_D < IDEAL_ROPELENGTH[knot_name]:
        raise ValueError(f"--L {args.L:g} / --D {args.D:g} = {L_over_D:.3f} is below the ideal {knot_name} knot's "
                         f"ropelength {IDEAL_ROPELENGTH[knot_name]}: no such knot exists (raise --L or lower --D)")
    return knot_name


def _checked_rod(args):
    """Checks the rod and the twist range of ``args`` (resolving --N); ValueError naming the flag."""
    from ..model.scenes import MIN_TREFOIL_NODES
    from ..validation import check_finite, check_int_at_least, check_poisson_ratio, check_positive

    D, L = check_positive("D", args.D), check_positive("L", args.L)
    knot_name = _checked_knot(args)
    need = math.ceil(L / D - 1e-9)
    if args.N is None:
        args.N = STUDY_NODES if args.accuracy is None else max(ACCURACY_NODES, need)
    check_int_at_least("N", args.N, MIN_TREFOIL_NODES)
    if args.N < need:
        raise ValueError(f"--N {args.N} gives edges of {L / args.N / D:.2f} D: self-contact needs edges no longer "
                         f"than the diameter: raise --N to at least L/D = {need}")
    check_positive("E", args.E)
    check_poisson_ratio("nu", args.nu)
    if args.contact_stiffness is not None:
        check_positive("contact_stiffness", args.contact_stiffness)
    for name in ("phi_min", "phi_max"):
        check_finite(name, getattr(args, name))
    if not args.phi_min < 0.0 < args.phi_max:
        raise ValueError(f"--phi-min must be < 0 < --phi-max, got --phi-min {args.phi_min / math.pi:g}pi, "
                         f"--phi-max {args.phi_max / math.pi:g}pi")
    check_positive("step", args.step)
    check_positive("tol", args.tol)
    return knot_name


def _options(args, knot_name):
    """The ``KnotStudyOptions`` of checked ``args``."""
    from ..model.scenes import DEFAULT_CONTACT_STIFFNESS
    from ..studies.runs.trefoil import KnotStudyOptions

    trefoil = args.command == "trefoil"
    return KnotStudyOptions(
        D=args.D, L=args.L, N=args.N, E=args.E, nu=args.nu,
        contact_stiffness=DEFAULT_CONTACT_STIFFNESS if args.contact_stiffness is None else args.contact_stiffness,
        chirality=args.chirality if trefoil else None, knot=None if trefoil else knot_name,
        curve=None if trefoil else args.curve, lk0=getattr(args, "lk0", None), phi_min=args.phi_min,
        phi_max=args.phi_max, step=args.step, tol=args.tol, out=args.out, fresh=args.fresh, serial=args.serial,
        stable_only=args.stable_only, extrapolation=not args.no_extrapolation, figures=not args.no_figures,
        vtk=args.vtk, accuracy=args.accuracy, N_max=args.N_max)


def _check_memory(n_nodes):
    from ..studies.runs.trefoil import check_knot_memory

    try:
        check_knot_memory(n_nodes)
    except ValueError as exc:
        raise ValueError(str(exc).replace("use N at most", "use --N at most")) from None


def run(args):
    """Runs ``jaxrod trefoil`` or ``jaxrod knot`` with the parsed ``args``; returns the exit status."""
    from .common import use_files_only_backend

    use_files_only_backend()
    from ..io.locking import folder_lock
    from ..studies.runs.trefoil import check_resumable, study_scene

    knot_name = _checked_rod(args)
    output_folder(args.out)
    args.hold(folder_lock(args.out))  # one run per folder, taken before any compilation
    options = _options(args, knot_name)
    if args.accuracy is not None:
        from ..validation import check_positive

        check_positive("accuracy", args.accuracy)
        if args.N_max < 4 * args.N - 3:
            raise ValueError(f"--N-max {args.N_max} leaves fewer than three levels from --N {args.N} "
                             f"(N, 2N-1, 4N-3): give --N-max at least {4 * args.N - 3}")
        _check_memory(args.N_max)
        return _accuracy(args, study_scene(options), options)
    _check_memory(args.N)
    scene = study_scene(options)
    check_resumable(scene, options)  # a folder of another run: refused now, not after the compilation
    return _study(args, scene, options)


def _study(args, scene, options):
    """The twist study, its progress on stderr and its result on stdout."""
    from ..studies.runs.trefoil import run_knot_study

    bar = Progress(args, (args.phi_max - args.phi_min) / math.pi, args.command)
    lk0 = "given" if getattr(args, "lk0", None) is not None else "the integer nearest the writhe as drawn"
    bar.say(f"{scene.name}: D = {args.D}, L = {args.L}, N = {args.N}, nu = {args.nu}, "
            f"kappa_c = {options.contact_stiffness}, Lk0 = {scene.Lk0:g} ({lk0}); "
            f"phi from {args.phi_min / math.pi:+.3f} pi to {args.phi_max / math.pi:+.3f} pi; writing {args.out}/")
    bar.say(args.compile_notice)
    reached, counts = {"plus": 0.0, "minus": 0.0}, {"steps": 0}

    def on_point(point):
        direction = point.direction
        reached[direction] = max(reached[direction], abs(point.equilibrium.phi) / math.pi)
        counts["steps"] += 1
        bar.update(reached["plus"] + reached["minus"], steps=counts["steps"], branch=point.branch)

    study = run_knot_study(scene, options, progress=bar.say, on_point=on_point, on_followed=bar.close)
    if args.json:
        print(json.dumps(study.summary))
    else:
        _print_study(args, study.summary)
    return 0


def _print_study(args, summary):
    for key in ("phi_plus", "phi_minus"):
        v = summary[key]
        print(f"{key:10s} = " + ("none in range" if v is None else f"{v:+.6f} rad = {v / math.pi:+.5f} pi"))
        error = summary.get(key + "_error")
        if v is not None and error is not None:  # not located on its extended system: the study's bracket
            why = "--stable-only" if getattr(args, "stable_only", False) else "see the progress lines"
            print(f"{'':10s}   +- {error / math.pi:.1e} pi: the study's bracket; this end was not located on its "
                  f"extended system ({why})")
        ext = summary.get(key + "_extrapolated")
        if ext is not None:
            print(f"{'':10s}   at N = {args.N}, not converged in N: extrapolated {ext['value_over_pi']:+.3f} pi "
                  f"+- {ext['error_over_pi']:.2f} pi (from N = {ext['N'][0]} and {ext['N'][1]}, order 2 assumed; "
                  f"--accuracy 0.01pi for a converged value)")
    total = summary.get("seconds_total")
    resumed = f" ({total:.1f} s with the interrupted runs)" if total and total > summary["seconds"] + 0.05 else ""
    side = summary.get("tightening_side")
    if side == "equal":
        side = "neither (the two sides are mirror images within round-off)"
    print(f"tightening side: {side}; time {summary['seconds']:.1f} s{resumed}; data in {args.out}/")


def _accuracy(args, scene, options):
    """--accuracy: both sides' first branch ends converged in N, their progress on stderr and
    their values on stdout; exit status 1 where a side did not converge."""
    from ..studies.runs.accuracy import accuracy_levels, run_accuracy

    bar = Progress(args, 0, args.command)
    bar.say(f"{scene.name}: D = {args.D}, L = {args.L}, nu = {args.nu}, kappa_c = {options.contact_stiffness}; "
            f"critical twists to {args.accuracy / math.pi:g} pi, N = {', '.join(map(str, accuracy_levels(options)))} "
            f"at most; writing {args.out}/")
    bar.say(args.compile_notice)
    try:
        converged = run_accuracy(scene, options, progress=bar.say)
    finally:
        bar.close()
    if args.json:
        print(json.dumps(converged.summary))
    else:
        for side, key in (("plus", "phi_plus"), ("minus", "phi_minus")):
            r = converged.convergence[side]
            ns = "/".join(str(lv.N) for lv in r.levels)
            if r.extrapolation is None:  # fewer than two levels: no error estimate, maybe no end
                found = "no end" if r.phi_star is None else f"{r.phi_star / math.pi:+.5f} pi, no error estimate"
                print(f"{key:10s} = {found} (N = {ns or args.N}): NOT CONVERGED: {r.reason}")
                continue
            print(f"{key:10s} = {r.phi_star / math.pi:+.5f} pi +- {r.error / math.pi:.1e} pi "
                  f"(N = {ns}, order {r.extrapolation.order:.2f}) " + ("" if r.reached else f"NOT CONVERGED: {r.reason}"))
        print(f"time {converged.seconds:.1f} s; data in {args.out}/")
    return 0 if converged.reached else 1
