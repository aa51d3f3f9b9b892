"""``jaxrod helix``: localized helical buckling of a clamped rod against NvdHT 2002 (the study:
``jaxrod.studies.runs.helix``)."""
from __future__ import annotations

import json
import math
import sys

from .common import NO_CACHE_HELP_LONG, Progress, add_quiet_and_cache, output_folder, parse_angle

NAME = "helix"

HELP = """\
Localized helical buckling of a clamped rod (Neukirch, van der Heijden & Thompson 2002, J. Mech.
Phys. Solids 50, eqs. 14-15): a rod of length L clamped at both ends along one axis, the far clamp
moved closer by the end shortening d L and turned by the end rotation R, solved from the analytic
loop by Newton. Give the loads (--m M L/B, --t T L^2/B) or the imposed ends (--d, --R; either
sign: the mirror image has (-m, t)); the material by --nu (C/B = 1/(1 + nu)), --gamma (C/B) or
--B and --C, and EA by --slenderness or --EA. Reports the end moment M and tension T (exact
derivatives of the energy), theta_max, Lk = Wr + Tw (= R / 2 pi), the Morse index, and the
analytic values beside them, with Richardson's extrapolation from N and about N/2 where both
resolve the loop. The formulas are those of an infinite inextensible rod: where the loop is not
localized (lambda = sqrt(t - m^2/4) < 13) or the stretch shifts t by more than 1e-4, the
analytic values are reported as not applicable (reference_valid: false, with the reason) and
no error is computed; --strict refuses such a case instead.
At given (d, R) the formulas have up to two loops (small and large t): --root stable (default)
solves each and takes the stable one (Morse index 0 under fixed ends; if none or both are, the
larger t), --root small / large takes that one, --root both reports both in full.
--sweep K also follows the loop along K end rotations from 0.8 R to 1.1 R at the same shortening
(M, T and stability along the path).

Writes into --out: helix.json (summary), centreline.csv, envelope.csv (s/L, theta numeric and
analytic), centreline.png, envelope.png and, with --sweep, path.csv and loads.png.

examples:
  jaxrod helix --m 20 --t 300 --N 240 --out results/helix
  jaxrod helix --d 0.13 --R 13pi --nu 0.3 --root large --sweep 9 --out results/helix_sweep
  jaxrod helix --d 0.1886 --R=-43.82 --B 2 --C 1 --root both
"""


def add_parser(sub, formatter_class):
    """Adds the helix command's parser to the subparsers ``sub``."""
    hx = sub.add_parser(NAME, help="localized helical buckling of a clamped rod with end shortening and "
                        "rotation, against NvdHT 2002 (M, T, stability, figures)", description=HELP,
                        formatter_class=formatter_class)
    hx.add_argument("--m", type=float, default=None, help="end moment M L/B (with --t)")
    hx.add_argument("--t", type=float, default=None, help="tension T L^2/B (with --m)")
    hx.add_argument("--d", type=float, default=None, help="end shortening / L, in (0, 1) (with --R)")
    hx.add_argument("--R", type=parse_angle, default=None, metavar="R", help="end rotation in rad, e.g. 10pi (with --d)")
    hx.add_argument("--nu", type=float, default=None,
                    help="Poisson ratio in (-1, 0.5]: C/B = 1/(1 + nu); nu = 0.5 where none of --nu, --gamma, --C is given")
    hx.add_argument("--gamma", type=float, default=None, help="twist over bending stiffness C/B, any positive value")
    hx.add_argument("--B", type=float, default=None,
                    help="bending stiffness B (1 where not given); m = M L/B and t = T L^2/B, L = 1")
    hx.add_argument("--C", type=float, default=None, help="twist stiffness C (C/B any positive value)")
    hx.add_argument("--EA", type=float, default=None, help="stretching stiffness EA (16 B / slenderness^2 where not given)")
    hx.add_argument("--root", choices=("stable", "small", "large", "both"), default="stable",
                    help="with --d/--R, which of the (up to two) analytic loops: stable (each solved, the one of Morse "
                         "index 0 taken), small or large t, or both (each reported in full) (default stable)")
    hx.add_argument("--strict", action="store_true",
                    help="refuse a case outside the analytic formulas' range (lambda < 13, or a stretch that shifts "
                         "t by more than 1e-4) instead of reporting it without the comparison")
    hx.add_argument("--no-extrapolate", action="store_true",
                    help="skip the coarse solve (N/2 + 1 nodes) for Richardson's extrapolation of m and t")
    hx.add_argument("--N", type=int, default=240, help="number of nodes (default 240; at least 6 per loop core "
                                                      "width L/lambda and 2 per radian of R)")
    hx.add_argument("--slenderness", type=float, default=2e-4,
                    help="rod diameter over length D/L: EA = 16 B / (D/L)^2 unless --EA (default 2e-4: inextensible)")
    hx.add_argument("--sweep", type=int, default=0, metavar="K",
                    help="also solve K end rotations from 0.8 R to 1.1 R at the same shortening (default 0)")
    hx.add_argument("--out", default=None, help="folder for helix.json, CSV files and figures (default: none)")
    hx.add_argument("--json", action="store_true", help="print one JSON object")
    add_quiet_and_cache(hx, NO_CACHE_HELP_LONG)


def run(args):
    """Runs ``jaxrod helix`` with the parsed ``args``; returns the exit status."""
    from .common import use_files_only_backend

    use_files_only_backend()
    from ..io.locking import folder_lock
    from ..studies.runs.helix import run_helix
    from ..studies.runs.helix_files import write_helix_files

    case = _case(args)
    if args.out:
        output_folder(args.out)
        args.hold(folder_lock(args.out))
    extrapolate = not args.no_extrapolate
    bar = Progress(args, len(case.resolved) + case.sweep + int(extrapolate), NAME, counting="states")
    _announce_helix_roots(bar.say, case)
    bar.say(args.compile_notice)
    try:
        solved = run_helix(case, root=args.root, extrapolate=extrapolate, progress=bar.say, on_state=bar.update)
    finally:
        bar.close()
    if solved.taken is None:
        return _no_helix_equilibrium(solved.solved)
    if args.out:
        names = write_helix_files(solved, args.out)
        bar.say(f"wrote {args.out}/{', '.join(names)}")
    if args.json:
        print(json.dumps(solved.result))
    else:
        _print_helix(args, solved)
    return 0


def _case(args):
    """The ``HelixCase`` of ``args``; ValueError (bad input) naming the flag."""
    from ..studies.runs.helix import helix_case
    from ..validation import check_int_at_least

    N = check_int_at_least("N", args.N, 8)
    B, C, nu, gamma, D, EA = _helix_material(args)
    sweep = check_int_at_least("sweep", args.sweep, 0)
    refs, n_found = _helix_roots_asked(args, gamma)
    return helix_case(N, B, C, nu, gamma, D, EA, sweep, refs, n_found, strict=args.strict)


def _helix_material(args):
    """(B, C, nu, gamma, D, EA): B from --B (default 1) and C = gamma B, gamma from one of --C,
    --gamma and --nu (default nu = 0.5); the slenderness D = D/L (below 0.1) and EA from --EA or
    16 B / D^2 (a solid round rod)."""
    from ..validation import check_poisson_ratio, check_positive

    B = 1.0 if args.B is None else check_positive("B", args.B)
    given = [flag for flag, v in (("--nu", args.nu), ("--gamma", args.gamma), ("--C", args.C)) if v is not None]
    if len(given) > 1:
        raise ValueError(f"give one of --nu, --gamma and --C (the twist stiffness), not {' and '.join(given)}")
    if args.C is not None:
        gamma = check_positive("C", args.C) / B
    elif args.gamma is not None:
        gamma = check_positive("gamma", args.gamma)
    else:
        gamma = 1.0 / (1.0 + check_poisson_ratio("nu", 0.5 if args.nu is None else args.nu))
    C, nu = gamma * B, 1.0 / gamma - 1.0
    D = check_positive("slenderness", args.slenderness)
    if not D < 0.1:
        raise ValueError(f"--slenderness (D/L) must be below 0.1, got {D!r}")
    EA = 16.0 * B / D ** 2 if args.EA is None else check_positive("EA", args.EA)
    return B, C, nu, gamma, D, EA


def _helix_given_by_loads(args):
    """True for --m and --t (the loads), False for --d and --R (the ends); ValueError unless one
    pair is given, in full."""
    by_loads, by_ends = args.m is not None or args.t is not None, args.d is not None or args.R is not None
    if by_loads == by_ends or (by_loads and (args.m is None or args.t is None)) or \
            (by_ends and (args.d is None or args.R is None)):
        raise ValueError("give either --m and --t (loads) or --d and --R (end shortening and rotation)")
    return by_loads


def _helix_roots_asked(args, gamma):
    """(refs, n_found): the analytic loops to solve, as (name, LocalizedHelix), for the loads or
    the ends given and --root, and how many loops the ends have (1 for given loads)."""
    from ..studies import endloads as el
    from ..validation import check_finite, check_positive

    if _helix_given_by_loads(args):
        if args.root not in ("stable", "both"):
            raise ValueError(f"--root {args.root} chooses between the loops at given --d and --R; --m and --t give one")
        return [("only", el.localized_helix(check_finite("m", args.m), args.t, gamma))], 1
    d = check_positive("d", args.d)
    if not d < 1.0:
        raise ValueError(f"--d (end shortening / L) must be below 1, got {d!r}")
    found = el.localized_helix_from_shortening(d, check_finite("R", args.R), gamma)  # ascending in t
    if not found:
        raise ValueError(f"--d {d:g} --R {args.R:g}: no localized helix (NvdHT 2002 eqs. 14-15) has this end "
                         f"shortening and rotation at gamma = C/B = {gamma:.4g}: change --R or --d")
    return el.select_helix_roots(el.named_helix_roots(found), args.root), len(found)


def _announce_helix_roots(say, case):
    """The roots to solve, and those left out, on the progress line."""
    for name, h in case.resolved:
        say(f"localized helix ({name} root): m = {h.m:.6g}, t = {h.t:.6g}, gamma = {case.gamma:.4g}: d = {h.d:.6g}, "
            f"R = {h.R:.6g} rad ({h.R / (2 * math.pi):.4g} turns), lambda = {h.lam:.4g}; N = {case.N}")
    for name, h, why in case.refused:
        say(f"{name} root (m = {h.m:.6g}, t = {h.t:.6g}) left out: {why}")


def _no_helix_equilibrium(solved):
    """Exit status 1, with the first root's failure on stderr and what to change."""
    exc = next(iter(solved.values())).error
    print(f"jaxrod: error: no equilibrium found near the analytic loop: raise --N (at least 6 edges per "
          f"loop core L/lambda), or move the loads away from the straight rod's threshold m^2 = 4 t "
          f"({str(exc).splitlines()[0][:160]})", file=sys.stderr)
    return 1


def _helix_number(v):
    return "-" if v is None else f"{v:.6g}"


def _print_helix(args, run):
    """The helix summary as text on stdout: the roots (where several), the table of each root
    shown (the taken one; all solved with --root both), the extrapolation, envelope and time."""
    case, solved, result = run.case, run.solved, run.result
    taken = result["root"]
    if len(result["roots"]) > 1 or case.refused:
        _print_helix_roots(result["roots"])
    if case.n_found > 1:
        print(f"taken: the {taken} root ({result['root_reason']})")
    shown = [name for name, _ in case.refs if name in solved and solved[name].eq is not None] \
        if args.root == "both" else [taken]
    for name in shown:
        if len(shown) > 1:
            print(f"-- {name} root" + (" (taken)" if name == taken else ""))
        _print_helix_table(solved[name], case.checks[name])
    if result["m_extrapolated"] is not None:
        err = "" if not result["reference_valid"] else (f"; errors {result['m_extrapolated_rel_error']:+.1e}, "
                                                        f"{result['t_extrapolated_rel_error']:+.1e}")
        print(f"Richardson    m = {result['m_extrapolated']:.6g}, t = {result['t_extrapolated']:.6g}  "
              f"(N = {result['N_coarse']} and {case.N}{err}" + (f"; the {taken} root)" if len(shown) > 1 else ")"))
    if result["reference_valid"]:
        print(f"envelope L1   {result['envelope_L1']:>14.3e}")
    print(f"time          {result['seconds']:>14.2f} s")


def _print_helix_roots(roots):
    for row in roots:
        err = "" if row["m_rel_error"] is None else \
            f", errors m {row['m_rel_error']:+.2e}, t {row['t_rel_error']:+.2e}"
        got = ("not solved" + (f": {row['note']}" if row.get("note") else "")) if row["m"] is None else \
            f"m = {row['m']:.6g}, t = {row['t']:.6g}, Morse index {row['morse']}{err}"
        print(f"{row['root']} root (analytic m = {row['m_analytic']:.6g}, t = {row['t_analytic']:.6g}): {got}"
              + ("" if row["reference_valid"] else " [reference not applicable]"))


def _print_helix_table(root, check):
    """One solved root's values beside the analytic ones (only its own where they do not apply)."""
    h, st, fmt = root.ref, root.state, _helix_number
    rows = [("m = M L/B", st["m"], h.m), ("t = T L^2/B", st["t"], h.t),
            ("theta_max", st["theta_max"], h.theta_max), ("Lk", st["Lk"], st["Lk_expected"]),
            ("Wr", st["Wr"], h.Wr), ("Tw", st["Tw"], h.Tw)]
    if check.valid:
        print(f"{'':14s}{'jaxrod':>14s}{'analytic':>14s}")
        for label, a, b in rows:
            print(f"{label:14s}{fmt(a):>14s}{fmt(b):>14s}")
    else:
        print(f"analytic reference (NvdHT 2002): not applicable: {check.reason}")
        print(f"{'':14s}{'jaxrod':>14s}")
        for label, a, _ in rows[:3]:
            print(f"{label:14s}{fmt(a):>14s}")
        print(f"{'Lk':14s}{fmt(st['Lk']):>14s}  (R / 2 pi = {st['Lk_expected']:.6g})")
        for label, a, _ in rows[4:]:
            print(f"{label:14s}{fmt(a):>14s}")
    print(f"Morse index   {st['morse']:>14d}  ({'stable' if st['stable'] else 'unstable'} under fixed ends)")
