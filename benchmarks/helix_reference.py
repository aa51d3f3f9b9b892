"""`jaxrod helix` at N = 400 against Neukirch, van der Heijden & Thompson (2002), eqs. 14-15: for
imposed ends (d, R) of either sign and the material set by --B and --C (C/B = 2/3, 1 and 0.5, the
last outside nu in (-1, 0.5]), m = ML/B and t = TL^2/B as solved at N = 400 and as extrapolated by
Richardson from N = 201 and 400 (the command's own), against the analytic loop (the localized,
larger-t root, --root large); the mirror pairs' (m, t) -> (-m, t); and stiff rods, B = 1e-3 and
EA = 1e3 ... 1e9 (EA L^2/B = 1e6 ... 1e12), t against the stretch's first-order shift.

Writes benchmarks/results/helix_reference.json.
Run: OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/helix_reference.py
"""
import contextlib
import io
import json
import os
import time

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

from jaxrod.studies import endloads as el  # noqa: E402
from jaxrod.cli import main as cli  # noqa: E402

from _bench import SMOKE, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)

N = pick(400, 180)  # small mode: its coarse level N/2 + 1 = 91 and 180 are the N of helical_buckling and tension_twist, whose programs it shares
# (m, t, B, C): the loop whose (d, R) is imposed; lambda = 14.1, 16.6, 13.9
LOOPS = pick(((20.0, 300.0, 2.0, 4.0 / 3.0), (10.0, 300.0, 1.0, 1.0), (15.0, 250.0, 1.0, 0.5)), ((20.0, 300.0, 2.0, 4.0 / 3.0),))
EAS = pick((1e3, 1e5, 1e7, 1e9), (1e5, 1e7))  # with B = 1e-3
HERE = os.path.dirname(os.path.abspath(__file__))


def run(argv):
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        rc = cli(["helix", *argv, "--json", "--quiet"])
    assert rc == 0, (argv, rc)
    return json.loads(out.getvalue())


def main():
    rows = []
    for m, t, B, C in LOOPS:
        ref = el.localized_helix(m, t, C / B)
        for sign in (1.0, -1.0):
            t0 = time.perf_counter()
            res = run(["--d", repr(ref.d), f"--R={sign * ref.R!r}", "--B", repr(B), "--C", repr(C), "--N", str(N),
                       "--root", "large"])
            row = {k: res[k] for k in ("d", "R", "B", "C", "gamma", "lambda", "m", "t", "m_analytic", "t_analytic",
                                       "m_rel_error", "t_rel_error", "m_extrapolated", "t_extrapolated",
                                       "m_extrapolated_rel_error", "t_extrapolated_rel_error", "reference_valid",
                                       "morse", "N_coarse")}
            row["seconds"] = time.perf_counter() - t0
            rows.append(row)
            print(f"d = {row['d']:.5f}, R = {row['R']:+.4f}, C/B = {row['gamma']:.3g}: m {row['m']:+.5f} "
                  f"(err {row['m_rel_error']:+.1e}), t {row['t']:.4f} (err {row['t_rel_error']:+.1e}); "
                  f"Richardson errors m {row['m_extrapolated_rel_error']:+.1e}, "
                  f"t {row['t_extrapolated_rel_error']:+.1e}; "
                  f"Morse {row['morse']}; {row['seconds']:.0f} s", flush=True)
    mirror = [abs(a["m"] + b["m"]) / abs(a["m"]) for a, b in zip(rows[0::2], rows[1::2])]
    mirror_t = [abs(a["t"] - b["t"]) / a["t"] for a, b in zip(rows[0::2], rows[1::2])]
    print(f"mirror pairs: |m+ + m-|/|m| <= {max(mirror):.1e}, |t+ - t-|/t <= {max(mirror_t):.1e}")
    stiff = []
    m, t = 20.0, 300.0
    ref = el.localized_helix(m, t, 2.0 / 3.0)
    for EA in EAS:
        t0 = time.perf_counter()
        res = run(["--m", "20", "--t", "300", "--B", "1e-3", "--gamma", repr(2.0 / 3.0), "--EA", repr(EA),
                   "--N", str(N), "--no-extrapolate"])
        stiff.append({"EA": EA, "EA_L2_over_B": EA / 1e-3, "m": res["m"], "t": res["t"], "morse": res["morse"],
                      "reference_valid": res["reference_valid"], "reference_reason": res["reference_reason"],
                      "stretch_shift": el.stretch_shift(ref, EA / 1e-3), "seconds": time.perf_counter() - t0})
    t_stiff = stiff[-2]["t"]
    for s in stiff:
        s["t_vs_EA_1e7"] = s["t"] / t_stiff - 1.0
        print(f"EA = {s['EA']:.0e} (EA L^2/B = {s['EA_L2_over_B']:.0e}): m {s['m']:.6f}, t {s['t']:.4f}, "
              f"t / t(EA = 1e7) - 1 = {s['t_vs_EA_1e7']:+.1e} (stretch estimate {s['stretch_shift']:.1e}), "
              f"Morse {s['morse']}, reference valid {s['reference_valid']}; {s['seconds']:.0f} s", flush=True)
    with open(os.path.join(results_dir(), "helix_reference.json"), "w") as f:
        json.dump(with_provenance({"N": N, "rows": rows, "mirror_m": mirror, "mirror_t": mirror_t, "stiff": stiff}),
                  f, indent=2)


if __name__ == "__main__":
    main()
