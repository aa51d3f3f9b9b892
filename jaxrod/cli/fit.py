"""``jaxrod fit``: scene parameters fitted to measured critical twists."""
from __future__ import annotations

import json
import math
import os
import sys

from .common import add_quiet_and_cache, output_folder, parse_angle

NAME = "fit"

HELP = """\
Fit rod parameters (the Poisson ratio nu, i.e. the twist-to-bend ratio B/C = 1 + nu, or others)
to measured critical twists by weighted least squares with the exact Jacobian (the implicit
function theorem at each located end). The measurements are a CSV file with the header
  knot,N,D,L,side,phi,sigma
one row per measured onset: knot 3_1, 4_1, 5_1, 5_2 (or ring: Michell's ring of length L), the
node count N, the rod's diameter D and length L, the side (plus: phi > 0, minus), the measured
critical twist phi and its standard error sigma (radians, or e.g. 6.5pi). Prints the estimates
with their standard errors and each measurement's residual.

examples:
  jaxrod fit onsets.csv --out results/fit
  jaxrod fit onsets.csv --parameters nu,contact_stiffness --json
"""


def add_parser(sub, formatter_class):
    """Adds the fit command's parser to the subparsers ``sub``."""
    f = sub.add_parser(NAME, help="fit rod parameters to measured critical twists (CSV), with standard errors",
                       description=HELP, formatter_class=formatter_class)
    f.add_argument("measurements", help="CSV file: knot,N,D,L,side,phi,sigma (one row per measured onset)")
    f.add_argument("--parameters", default="nu",
                   help="comma-separated names among nu, B, C, EA, D, contact_stiffness (default nu)")
    f.add_argument("--nu", type=float, default=0.5, help="Poisson ratio the fit starts from (default 0.5)")
    f.add_argument("--phi-min", type=parse_angle, default=-16 * math.pi, help="search range, below 0 (default -16pi)")
    f.add_argument("--phi-max", type=parse_angle, default=16 * math.pi, help="search range, above 0 (default 16pi)")
    f.add_argument("--out", default=None, help="folder for fit.json (default: none)")
    f.add_argument("--json", action="store_true", help="print one JSON object")
    add_quiet_and_cache(f)


def run(args):
    """Runs ``jaxrod fit`` with the parsed ``args``; returns the exit status."""
    from .common import use_files_only_backend

    use_files_only_backend()
    from ..io.atomic import write_json
    from ..studies.runs.fit import fit_file, fit_json

    parameters = tuple(p.strip() for p in args.parameters.split(",") if p.strip())
    if not parameters:
        raise ValueError("--parameters: name at least one parameter, e.g. nu")
    if not args.phi_min < 0.0 < args.phi_max:
        raise ValueError(f"--phi-min must be < 0 < --phi-max, got {args.phi_min}, {args.phi_max}")
    if args.out:
        output_folder(args.out)
    if not args.quiet:
        print(f"fitting {', '.join(parameters)} to {args.measurements}", file=sys.stderr, flush=True)
    rows, fit = fit_file(args.measurements, parameters, args.nu, args.phi_min, args.phi_max)
    result = fit_json(rows, fit)
    if args.out:
        write_json(os.path.join(args.out, "fit.json"), result)
    if args.json:
        print(json.dumps(result))
        return 0 if fit.converged else 1
    for name, p in result["parameters"].items():
        print(f"{name} = {p['value']:.8g} +- {p['standard_error']:.2g}")
    print(f"chi2 = {fit.chi2:.4g} with {result['degrees_of_freedom']} degrees of freedom; "
          f"{'converged' if fit.converged else 'NOT converged'}: {fit.reason}")
    for m in result["measurements"]:
        print(f"  {m['knot']} N={m['N']} D={m['D']:g} L={m['L']:g} {m['side']:5s}: measured {m['phi'] / math.pi:+.5f} pi, "
              f"fit {m['phi_fit'] / math.pi:+.5f} pi, residual {m['residual'] / m['sigma']:+.2f} sigma")
    return 0 if fit.converged else 1
