"""Same answers, and command 1 no slower: the release before the redesign against the working tree.

    python benchmarks/redesign_same_answers.py                      # baseline 7b060a4, every case
    python benchmarks/redesign_same_answers.py --cases command1,michell --reps 1

The baseline's ``jaxrod/`` comes from ``git archive`` into a temporary folder. Every case runs the
``jaxrod`` command line once per version, each in a process of its own (``PYTHONPATH`` set to the
version's folder, ``jaxrod.cli.console_main``), each version with its own persistent compile cache
(``XDG_CACHE_HOME`` in a fresh folder; ``JAX_COMPILATION_CACHE_DIR`` unset), and compares what the
two print or write:

- ``command1``: ``jaxrod trefoil --D 8 --L 292 --N 121 --phi-min -12pi --phi-max 14pi --out DIR``: the
  located ends (``diagram.json``: ``ends[*].phi_over_pi``), to 1e-10 (in units of pi). Also the speed:
  each version's first process compiles (cold); then ``--reps`` warm processes per version on their
  caches, alternating old and new, each timed as a whole process (interpreter start to exit).
- ``accuracy``: ``jaxrod trefoil --D 8 --L 292 --accuracy 0.01pi --json``: phi_plus, phi_minus (rad) and
  every other number of the summary, to 1e-8.
- ``helix``: ``jaxrod helix --m 20 --t 300 --N 240 --json`` (the README's first example; the command
  has no default loads): every number, to 1e-8.
- ``critical_curve``: ``jaxrod critical-curve --ratios 0.018:0.032:0.002 --N 61 --json`` (the README's
  example): every number of every row, to 1e-8.
- ``michell``: ``jaxrod michell --N 1024 --json``: phi_star (rad) to 1e-12, every other number to 1e-8.
- ``michell_api``: ``critical_twist(michell_ring(N=1024, nu=0.5), 0, 2 phi_a, ContinuationOptions(step=
  phi_a/8, tol=1e-6 pi))``, the call behind the acceptance's phi* = 16.324629844619217 rad: phi_star
  against each other and against that value, to 1e-12.

A number passes where ``|new - old| <= tol * max(1, |old|)``; timings (``seconds``) are left out. Keys
that only one version prints are listed, not failed. Writes redesign_same_answers.md and .json to
``benchmarks/results`` (rewritten after each case, so an interrupted run keeps what it finished).

Small mode (``--smoke``): the helix case at N = 90 (one ``--json`` command, the cheapest to compile:
one process a version); the other cases only when named with ``--cases`` (their small inputs: command 1
at N = 41 over -0.5pi ... 0.5pi, its cold process only, no timing; the Michell cases at N = 64;
critical-curve at one ratio and N = 41; the accuracy mode from N = 37).
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

from _bench import fmt, pick, provenance, provenance_line, results_dir, with_provenance  # noqa: E402  (benchmarks/ is on the path)

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
BASELINE = "7b060a4"  # the last commit before "Move modules into layers"
LAUNCH = "import sys; from jaxrod.cli import console_main; sys.argv = ['jaxrod'] + sys.argv[1:]; console_main()"
IGNORED_KEYS = {"seconds", "out"}  # wall times and the run's own --out folder differ from run to run
# The reference of the acceptance: michell_ring(N=1024, nu=0.5) through the library's critical_twist with
# ContinuationOptions(step=phi_a/8, tol=1e-6 pi) (BENCHMARKS.md; the command line's own scan, with its
# --tol, lands elsewhere within its tolerance).
MICHELL_API = """
import json, math, sys
from jaxrod.continuation import ContinuationOptions, critical_twist
try:
    from jaxrod.model.scenes import michell_ring
except ImportError:  # the baseline's layout
    from jaxrod.scenes import michell_ring
N = int(sys.argv[1])
phi_a = 2 * math.pi * math.sqrt(3) * 1.5
point = critical_twist(michell_ring(N=N, nu=0.5), 0.0, 2 * phi_a,
                       ContinuationOptions(step=phi_a / 8, tol=1e-6 * math.pi))
print(json.dumps({"N": N, "phi_star": point.phi, "phi_error": point.phi_error}))
"""

COMMAND1 = pick(["trefoil", "--D", "8", "--L", "292", "--N", "121", "--phi-min", "-12pi", "--phi-max", "14pi"],
                ["trefoil", "--D", "8", "--L", "292", "--N", "41", "--phi-min", "-0.5pi", "--phi-max", "0.5pi"])
# Each case: the arguments (after the command), the tolerance of its numbers and its unit, and the
# top-level numbers the acceptance names (headlines), each with its own tolerance.
CASES = {
    "command1": {"args": COMMAND1, "tol": 1e-10, "unit": "pi"},  # diagram.json's phi_over_pi
    "michell": {"args": ["michell", "--N", pick("1024", "64"), "--json"], "tol": 1e-8,
                "headlines": [("phi_star", 1e-12)], "unit": "rad"},
    "michell_api": {"code": MICHELL_API, "args": [pick("1024", "64")], "tol": 1e-12, "unit": "rad",
                    "headlines": [("phi_star", 1e-12)], "reference": pick({"phi_star": 16.324629844619217}, {})},
    "helix": {"args": ["helix", "--m", "20", "--t", "300", "--N", pick("240", "90"), "--json"], "tol": 1e-8},
    "critical_curve": {"args": ["critical-curve", "--ratios", pick("0.018:0.032:0.002", "0.028:0.028:0.001"),
                                "--N", pick("61", "41"), "--json"], "tol": 1e-8},
    "accuracy": {"args": pick(["trefoil", "--D", "8", "--L", "292", "--accuracy", "0.01pi", "--json"],
                              ["trefoil", "--D", "8", "--L", "292", "--N", "37", "--accuracy", "1pi", "--N-max",
                               "145", "--json"]),
                 "tol": 1e-8, "headlines": [("phi_plus", 1e-8), ("phi_minus", 1e-8)], "unit": "rad"},
}


def extract(commit, into):
    """The ``jaxrod/`` folder of ``commit`` under ``into`` (git archive)."""
    os.makedirs(into, exist_ok=True)
    archive = subprocess.run(["git", "-C", REPO, "archive", commit, "jaxrod"], check=True, capture_output=True)
    subprocess.run(["tar", "-x", "-C", into], input=archive.stdout, check=True)
    return into


def run_cli(source, args, cache, scratch, timeout=None, code=LAUNCH):
    """One ``jaxrod`` process (or ``code`` with ``args``) of the version in ``source`` with its
    compile cache under ``cache``.
    -> {"seconds", "returncode", "stdout", "stderr"}. Runs in ``scratch`` (never in the repository,
    whose ``jaxrod/`` would shadow the baseline's)."""
    env = dict(os.environ, PYTHONPATH=source, XDG_CACHE_HOME=cache)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    env.pop("JAXROD_PROGRAMS", None)
    t = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-c", code, *args], cwd=scratch, env=env, capture_output=True,
                              text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"seconds": time.perf_counter() - t, "returncode": None, "stdout": "", "stderr": "timed out"}
    return {"seconds": time.perf_counter() - t, "returncode": proc.returncode, "stdout": proc.stdout,
            "stderr": proc.stderr}


def last_json(stdout):
    """The JSON object a ``--json`` command printed (its last line), or None."""
    lines = stdout.strip().splitlines()
    try:
        return json.loads(lines[-1]) if lines else None
    except json.JSONDecodeError:
        return None


def flatten(obj, prefix=""):
    """{"a.b[0].c": leaf} for every leaf of a JSON object (IGNORED_KEYS left out)."""
    if isinstance(obj, dict):
        out = {}
        for key, value in obj.items():
            if key not in IGNORED_KEYS:
                out.update(flatten(value, f"{prefix}.{key}" if prefix else key))
        return out
    if isinstance(obj, list):
        out = {}
        for i, value in enumerate(obj):
            out.update(flatten(value, f"{prefix}[{i}]"))
        return out
    return {prefix: obj}


def is_number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def compare(old, new, tol):
    """Every leaf of two JSON objects side by side: the largest difference of the numbers (absolute,
    and scaled by max(1, |old|)), the leaves that differ beyond ``tol`` and those only one side has."""
    a, b = flatten(old), flatten(new)
    worst_abs, worst_key, failures, unequal = 0.0, None, [], []
    for key in sorted(set(a) & set(b)):
        x, y = a[key], b[key]
        if is_number(x) and is_number(y):
            if math.isnan(x) and math.isnan(y):
                continue
            diff = abs(y - x)
            if not diff <= worst_abs:
                worst_abs, worst_key = diff, key
            if not diff <= tol * max(1.0, abs(x)):
                failures.append({"key": key, "old": x, "new": y, "diff": diff})
        elif x != y:
            unequal.append({"key": key, "old": x, "new": y})
    return {"compared": len(set(a) & set(b)), "max_abs_diff": worst_abs, "max_diff_key": worst_key,
            "failures": failures, "unequal_non_numbers": unequal,
            "only_old": sorted(set(a) - set(b)), "only_new": sorted(set(b) - set(a))}


def headline_diff(old, new, key, tol):
    """The difference of one top-level number, against its own tolerance."""
    x, y = (old or {}).get(key), (new or {}).get(key)
    diff = None if not (is_number(x) and is_number(y)) else abs(y - x)
    return {"key": key, "old": x, "new": y, "diff": diff, "tol": tol, "ok": diff is not None and diff <= tol}


def reference_diff(new, key, value, tol):
    """One top-level number of the new version against the acceptance's stated value."""
    y = (new or {}).get(key)
    diff = abs(y - value) if is_number(y) else None
    return {"key": f"{key} against the stated {value!r}", "old": value, "new": y, "diff": diff, "tol": tol,
            "ok": diff is not None and diff <= tol}


def ends_of(out_dir):
    """The located ends of a trefoil study (``diagram.json``: ``ends[*].phi_over_pi``), or None."""
    path = os.path.join(out_dir, "diagram.json")
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return {"ends": [e.get("phi_over_pi") for e in json.load(f).get("ends", [])]}


class Sides:
    """The two versions, each with its source folder and its own compile cache; fresh scratch folders."""

    def __init__(self, tmp, baseline):
        self.tmp = tmp
        self.source = {"old": extract(baseline, os.path.join(tmp, "old")), "new": REPO}
        self.cache = {side: os.path.join(tmp, f"cache-{side}") for side in self.source}
        self.count = 0

    def scratch(self):
        self.count += 1
        path = os.path.join(self.tmp, f"run{self.count}")
        os.makedirs(path)
        return path

    def run(self, side, args, timeout=None, out=False, code=None):
        """One process of ``side``: the command line (``code`` None) with ``--quiet``, or ``code``;
        with ``out``, a fresh ``--out`` folder (a study resumes from its ``--out``, so every run gets a
        new one). -> (run record, out folder)."""
        scratch = self.scratch()
        out_dir = os.path.join(scratch, "out")
        full = [*args] if code else [*args, "--quiet"] + (["--out", out_dir] if out else [])
        record = run_cli(self.source[side], full, self.cache[side], scratch, timeout, code or LAUNCH)
        status = "ok" if record["returncode"] == 0 else f"exit {record['returncode']}"
        what = "python -c ..." if code else f"jaxrod {args[0]} ..."
        print(f"  {side}: {what} {record['seconds']:.1f} s ({status})", flush=True)
        if record["returncode"] not in (0, 1):
            print(record["stderr"][-2000:], file=sys.stderr, flush=True)
        return record, out_dir


def command1_case(sides, reps):
    """Command 1 on both versions: one cold process each, then ``reps`` warm ones alternating; the
    located ends of every run (each version's runs must agree among themselves too)."""
    args = CASES["command1"]["args"]
    runs = {"old": [], "new": []}
    for kind in ["cold"] + ["warm"] * reps:
        for side in ("old", "new"):
            record, out_dir = sides.run(side, args, out=True)
            runs[side].append({"kind": kind, "seconds": record["seconds"], "returncode": record["returncode"],
                               **(ends_of(out_dir) or {"ends": None})})
    old, new = runs["old"][-1], runs["new"][-1]
    result = {"args": args, "runs": runs, "comparison": compare({"ends": old["ends"]}, {"ends": new["ends"]},
                                                                CASES["command1"]["tol"]),
              "old_ends_repeat": len({json.dumps(r["ends"]) for r in runs["old"]}) == 1,
              "new_ends_repeat": len({json.dumps(r["ends"]) for r in runs["new"]}) == 1,
              "ends_old": old["ends"], "ends_new": new["ends"]}
    warm = {side: [r["seconds"] for r in runs[side] if r["kind"] == "warm"] for side in runs}
    if all(warm.values()):
        result["warm_s"] = {side: {"runs": warm[side], "median": statistics.median(warm[side]),
                                   "best": min(warm[side])} for side in warm}
        result["warm_ratio_new_over_old"] = result["warm_s"]["new"]["median"] / result["warm_s"]["old"]["median"]
    return result


def json_case(sides, name, timeout=None):
    """A ``--json`` command on both versions, its printed objects compared leaf by leaf."""
    case = CASES[name]
    outputs, seconds, codes, errors = {}, {}, {}, {}
    for side in ("old", "new"):
        record, _ = sides.run(side, case["args"], timeout=timeout, out=name in ("accuracy", "critical_curve"),
                              code=case.get("code"))
        outputs[side], seconds[side], codes[side] = last_json(record["stdout"]), record["seconds"], \
            record["returncode"]
        if record["returncode"] != 0:  # the last line of stderr says why (a traceback's is the error)
            errors[side] = (record["stderr"].strip().splitlines() or [""])[-1]
    result = {"args": case["args"], "seconds": seconds, "returncode": codes, "errors": errors,
              "comparison": compare(outputs["old"], outputs["new"], case["tol"]) if all(outputs.values()) else None}
    result["headlines"] = [headline_diff(outputs["old"], outputs["new"], key, tol)
                           for key, tol in case.get("headlines", ())]
    result["headlines"] += [reference_diff(outputs["new"], key, value, case["tol"])
                            for key, value in case.get("reference", {}).items()]
    return result


def passed(name, result):
    comparison = result.get("comparison")
    ok = comparison is not None and not comparison["failures"] and not comparison["unequal_non_numbers"]
    heads = result.get("headlines", [])
    return ok and all(h["ok"] for h in heads)


def case_line(name, result):
    """One row of the table of differences."""
    c = result.get("comparison")
    if c is None:
        return (f"| {name} | `{' '.join(result['args'])}` | none: a side printed nothing (exit "
                f"{result.get('returncode')}: {result.get('errors')}) | | | | FAIL |")
    heads = result.get("headlines", [])
    head = "; ".join(f"{h['key']}: {fmt(h['old'], '.15g')} / {fmt(h['new'], '.15g')}, diff {fmt(h['diff'], '.1e')}"
                     for h in heads) or "see below"
    only, key = f"{len(c['only_old'])} / {len(c['only_new'])}", c["max_diff_key"]
    tol = f"{CASES[name]['tol']:.0e}" + (f" ({CASES[name]['unit']})" if "unit" in CASES[name] else "")
    command = ("`critical_twist(michell_ring(N=N, nu=0.5), 0, 2 phi_a, ContinuationOptions(step=phi_a/8, "
               f"tol=1e-6 pi))`, N = {result['args'][0]}" if "code" in CASES[name] else f"`{' '.join(result['args'])}`")
    return (f"| {name} | {command} | {c['compared']}, tol {tol} | {c['max_abs_diff']:.1e} "
            f"({f'`{key}`' if key else 'all equal'}) | {head} | only old / new: {only} | "
            f"{'pass' if passed(name, result) else 'FAIL'} |")


def speed_lines(result):
    if "warm_s" not in result:
        return []
    w = result["warm_s"]
    runs = lambda side: ", ".join(f"{s:.1f}" for s in w[side]["runs"])  # noqa: E731
    cold = {side: next(r["seconds"] for r in result["runs"][side] if r["kind"] == "cold") for side in w}
    return ["", "## Command 1, warm (second and later processes on each version's own compile cache)", "",
            "| | old (7b060a4) | new (working tree) | new / old |", "|---|---|---|---|",
            f"| cold, first process (s) | {cold['old']:.1f} | {cold['new']:.1f} | {cold['new'] / cold['old']:.2f} |",
            f"| warm runs (s) | {runs('old')} | {runs('new')} | |",
            f"| warm median (s) | {w['old']['median']:.1f} | {w['new']['median']:.1f} | "
            f"{result['warm_ratio_new_over_old']:.2f} |",
            f"| warm best (s) | {w['old']['best']:.1f} | {w['new']['best']:.1f} | "
            f"{w['new']['best'] / w['old']['best']:.2f} |"]


def ends_lines(result):
    old, new = result.get("ends_old") or [], result.get("ends_new") or []
    lines = ["", "## Command 1's located ends (phi / pi)", "", "| old | new | diff |", "|---|---|---|"]
    for x, y in zip(old, new):
        lines.append(f"| {fmt(x, '+.10f')} | {fmt(y, '+.10f')} | "
                     f"{fmt(None if x is None or y is None else abs(y - x), '.1e')} |")
    if len(old) != len(new):
        lines.append(f"| {len(old)} ends | {len(new)} ends | different counts |")
    lines.append(f"\nEvery run of a version gave the same ends: old {result['old_ends_repeat']}, "
                 f"new {result['new_ends_repeat']}.")
    return lines


def write_results(results, meta, out):
    """redesign_same_answers.json (everything) and .md (the tables), from the cases done so far."""
    with open(os.path.join(out, "redesign_same_answers.json"), "w") as f:
        json.dump(with_provenance({**meta, "cases": results}), f, indent=2)
    lines = ["# Same answers: the release before the redesign against the working tree", "",
             provenance_line(), "",
             f"Baseline {meta['baseline']} (`git archive`), each command as a process of its own per version "
             f"(`benchmarks/redesign_same_answers.py`, {meta['timestamp']}; {meta['machine']}). A number passes "
             "where |new - old| <= tol * max(1, |old|).", "",
             "| case | command | numbers compared | largest difference | headline (old / new) | keys | |",
             "|---|---|---|---|---|---|---|"]
    lines += [case_line(name, r) for name, r in results.items()]
    for name, r in results.items():
        c = r.get("comparison") or {}
        for key in ("failures", "unequal_non_numbers", "only_old", "only_new"):
            if c.get(key):
                lines.append(f"\n{name}, {key}: `{json.dumps(c[key][:12])}`")
    if "command1" in results:
        lines += ends_lines(results["command1"]) + speed_lines(results["command1"])
    with open(os.path.join(out, "redesign_same_answers.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    return lines


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--baseline", default=BASELINE, help=f"the release to compare with (default {BASELINE})")
    # the small mode runs one case, a --json command through json_case, compare and the tables: each
    # case is a cold process per version (the two versions share no compiled code), 3-8 s even at
    # the small sizes, which the smoke test cannot spare for more than one
    p.add_argument("--cases", default=pick(",".join(CASES), "helix"),
                   help="comma-separated cases (default: all; small mode: helix)")
    p.add_argument("--reps", type=int, default=pick(2, 0),
                   help="warm processes per version for command 1 (default 2; small mode 0: no timing)")
    p.add_argument("--timeout", type=float, default=None, help="seconds allowed to one process (default none)")
    args = p.parse_args(argv)
    meta = {**provenance(), "baseline": args.baseline, "timestamp": time.strftime("%Y-%m-%d %H:%M:%S"),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
                       f"BLAS threads {os.environ.get('OPENBLAS_NUM_THREADS')}"}
    results, out = {}, results_dir()
    with tempfile.TemporaryDirectory(prefix="jaxrod-same-answers-") as tmp:
        sides = Sides(tmp, args.baseline)
        for name in args.cases.split(","):
            print(f"{name}:", flush=True)
            results[name] = (command1_case(sides, args.reps) if name == "command1"
                             else json_case(sides, name, args.timeout))
            lines = write_results(results, meta, out)
    print("\n".join(lines))
    return 0 if all(passed(n, r) for n, r in results.items()) else 1


if __name__ == "__main__":
    sys.exit(main())
