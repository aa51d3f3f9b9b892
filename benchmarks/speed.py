"""Speed: the current engine (working tree ``jaxrod``) against the baseline (commit 61e87f5: dense
``jax.hessian`` everywhere, full ``eigh``, branch ends by bisection), on the same problems, side by
side in one process.

Cases
  michell  Michell's ring, nu = 0.5: critical_twist(michell_ring(N, 0.5), 0, 2 phi_a,
           ContinuationOptions(step=phi_a/8, tol=1e-6 pi)), phi_a = 2 pi sqrt(3) (1 + nu). N = 64
           ... 1024 for the current engine, the baseline up to --baseline-max-N (it is O(N^3)). First
           call (JIT compile included) and a second, warm call; phi*, its error against phi_a; cost
           growth exponent in N.
  trefoil  Trefoil (D, L) = (8, 292) mm, branch end on each side: opening (0 -> 7.5 pi) and
           tightening (0 -> -12 pi), follow_twist(..., ContinuationOptions(step=0.5 pi, tol=2e-4 pi,
           switch=False)) from the knot relaxed at phi = 0. N = 61, 121 (+241 with --big); the
           baseline at N > 61 only with --baseline (3-15 min a side). At N = 61 the current engine
           is run twice (cold, warm).

How: the parent process plans the cases and runs each (case, N, side) in a child process of this
script (``--child``). The child imports jaxrod (working tree) first, then jaxrod_baseline (the
``jaxrod/`` folder of 61e87f5 from ``git archive``, renamed), and runs the current engine and then
the baseline on the same problem, one after the other, printing one JSON line per engine with its
times, results and peak resident memory (Linux high-water mark, reset between the engines). The
parent appends one CSV row per case x engine as each arrives (an interrupted run keeps its rows;
a new run skips rows already there unless --force), then writes BENCHMARKS.md and speed.png.

    python benchmarks/speed.py                      # full set (Michell, trefoil N = 61, 121)
    python benchmarks/speed.py --big --baseline     # + N = 241, baseline at every N (hours)
    python benchmarks/speed.py --quick              # tiny versions, into a temporary folder
    python benchmarks/speed.py --smoke              # smaller still (Michell N = 16 only)
    python benchmarks/speed.py --report-only        # tables and chart from speed.csv
    python benchmarks/speed.py --md-path /tmp/speed.md   # the report elsewhere (the docs' Performance page reads speed.csv)
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import gc  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402

from _bench import SMOKE, pick, provenance_line, results_dir  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
BASELINE_COMMIT = "61e87f5"
PI = math.pi
NU = 0.5
MICHELL_TOL = 1e-6 * PI
MICHELL_NS = (64, 128, 256, 512, 1024)
TREFOIL_D, TREFOIL_L = 8.0, 292.0
TREFOIL_NS = (61, 121)
TREFOIL_BIG_N = 241
TREFOIL_STEP = 0.5 * PI
TREFOIL_TOL = 2e-4 * PI
SIDES = {"opening": 7.5 * PI, "tightening": -12.0 * PI}
ENGINES = ("current", "baseline")  # the order in which a child runs them (see the report's notes)
MARK = "@@SPEED "
FIELDS = [
    "case", "N", "side", "phi_stop_over_pi", "engine", "status",
    "first_s", "warm_s", "compile_s", "relax_s", "follow_s", "warm_relax_s", "warm_follow_s",
    "phi_star", "phi_star_over_pi", "phi_error", "rel_error", "analytic_over_pi", "evals", "steps", "kind",
    "reason", "peak_rss_mb", "rss_start_mb", "peak_growth_mb", "rss_method", "process_maxrss_mb",
    "order_in_process", "engines_in_process", "jax_version", "jaxlib_version", "blas_threads", "cpu_count",
    "cpu_affinity", "loadavg", "current_src", "baseline_commit", "timestamp", "error",
]


def michell_analytic(nu=NU):
    return 2.0 * PI * math.sqrt(3.0) * (1.0 + nu)


# ----------------------------------------------------------------------------------------------
# Child: run one case with each requested engine, one JSON line per engine
# ----------------------------------------------------------------------------------------------

class PeakRSS:
    """Peak resident memory of a phase of this process. Linux keeps a high-water mark (VmHWM);
    writing 5 to /proc/self/clear_refs resets it to the current RSS, so the mark read at the end
    of a phase is that phase's own peak. Without that: the process peak so far (ru_maxrss)."""

    def __init__(self):
        self.resettable = self._reset()

    @staticmethod
    def _reset():
        try:
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")
            return True
        except OSError:
            return False

    @staticmethod
    def _status():
        vals = {}
        try:
            with open("/proc/self/status") as f:
                for line in f:
                    if line.startswith(("VmRSS:", "VmHWM:")):
                        vals[line.split(":")[0]] = int(line.split()[1]) / 1024.0  # kB -> MiB
        except OSError:
            pass
        return vals

    def begin(self):
        gc.collect()
        if self.resettable:
            self._reset()
        return self._status().get("VmRSS", float("nan"))

    def end(self, rss_start):
        maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB
        if self.resettable:
            peak, method = self._status().get("VmHWM", float("nan")), "VmHWM reset per engine"
        else:
            peak, method = maxrss, "ru_maxrss (process peak so far)"
        return dict(peak_rss_mb=round(peak, 1), rss_start_mb=round(rss_start, 1),
                    peak_growth_mb=round(peak - rss_start, 1), rss_method=method,
                    process_maxrss_mb=round(maxrss, 1))


def _source_hash(package_dir):
    h = hashlib.sha1()
    for name in sorted(os.listdir(package_dir)):
        if name.endswith(".py"):
            with open(os.path.join(package_dir, name), "rb") as f:
                h.update(name.encode() + b"\0" + f.read())
    return h.hexdigest()[:10]


def _say(text):
    print(text, flush=True)


def _call(jr, entry, scene, phi_start, phi_stop, options, observer, **kwargs):
    """entry(scene, phi_start, phi_stop, ...) with ``options`` (dict) and ``observer`` (dict of callbacks)
    as the engine takes them: one ContinuationOptions and one Observer (the current engine), keywords
    (the baseline, 61e87f5)."""
    if hasattr(jr, "Observer"):
        return entry(scene, phi_start, phi_stop, jr.ContinuationOptions(**options), observer=jr.Observer(**observer),
                     **kwargs)
    return entry(scene, phi_start, phi_stop, **options, **observer, **kwargs)


def _run_michell(jr, N, verbose):
    analytic = michell_analytic()
    scene = jr.michell_ring(N=N, nu=NU)
    progress = (lambda s: _say("    " + s)) if verbose else None

    def once():
        t = time.perf_counter()
        cp = _call(jr, jr.critical_twist, scene, 0.0, 2.0 * analytic, dict(step=analytic / 8.0, tol=MICHELL_TOL),
                   dict(progress=progress))
        return cp, time.perf_counter() - t

    cp1, first = once()
    _say(f"  first call {first:.2f} s: phi* = {cp1.phi / PI:.10f} pi")
    cp, warm = once()
    _say(f"  warm call  {warm:.2f} s: phi* = {cp.phi / PI:.10f} pi")
    if cp.phi != cp1.phi:
        _say(f"  note: the two calls differ by {(cp.phi - cp1.phi) / PI:.2e} pi")
    return dict(first_s=first, warm_s=warm, compile_s=first - warm, phi_star=cp.phi, phi_star_over_pi=cp.phi / PI,
                phi_error=cp.phi_error, rel_error=(cp.phi - analytic) / analytic, analytic_over_pi=analytic / PI,
                evals=len(cp.scan) + int(cp.hessian_evaluations), kind=f"multiplicity {cp.multiplicity}")


def _run_trefoil(jr, engine, N, stop, warm, verbose):
    del verbose  # the continuation's step lines are always shown (a side can take minutes)

    def once(tag):
        scene = jr.trefoil(D=TREFOIL_D, L=TREFOIL_L, N=N, nu=NU)
        t0 = time.perf_counter()
        if hasattr(jr, "RelaxOptions"):
            relaxed = jr.relax(scene, 0.0, options=jr.RelaxOptions(gtol=1e-9, with_stability=False))
        else:  # the baseline takes keywords
            relaxed = jr.relax(scene, 0.0, gtol=1e-9, with_stability=False)
        if engine == "baseline":  # 61e87f5: relax returns (equilibrium, scene with its contact list)
            relaxed, scene = relaxed
        t1 = time.perf_counter()
        _say(f"  [{tag}] relaxed in {t1 - t0:.1f} s (Wr = {relaxed.Wr:.4f})")
        path = _call(jr, jr.follow_twist, scene, 0.0, stop, dict(step=TREFOIL_STEP, tol=TREFOIL_TOL, switch=False),
                     dict(progress=lambda s: _say(f"    [{tag}] {s}")), start=relaxed)
        t2 = time.perf_counter()
        inst = path.instabilities[0] if path.instabilities else None
        phi = f"{inst.phi / PI:+.6f} pi" if inst else "none"
        _say(f"  [{tag}] followed in {t2 - t1:.1f} s, {len(path.points) - 1} steps: branch end {phi} ({path.reason})")
        return path, inst, t1 - t0, t2 - t1

    path, inst, relax_s, follow_s = once("cold")
    res = dict(first_s=relax_s + follow_s, relax_s=relax_s, follow_s=follow_s, steps=len(path.points) - 1,
               reason=path.reason)
    if inst is not None:
        res.update(phi_star=inst.phi, phi_star_over_pi=inst.phi / PI, phi_error=inst.phi_error, kind=inst.kind)
    if warm:
        path2, inst2, relax2, follow2 = once("warm")
        res.update(warm_s=relax2 + follow2, warm_relax_s=relax2, warm_follow_s=follow2,
                   compile_s=relax_s + follow_s - relax2 - follow2)
        if (inst2 is None) != (inst is None) or (inst is not None and inst2.phi != inst.phi):
            _say("  note: the warm run ended elsewhere: "
                 f"{inst2.phi / PI if inst2 else None} pi against {inst.phi / PI if inst else None} pi")
    return res


def child(args):
    t_import = time.perf_counter()
    import jaxrod  # first: float64 and single-threaded BLAS

    import jax

    # No persistent compilation cache (the CLI and the tests use one): first calls must compile.
    jax.config.update("jax_enable_compilation_cache", False)
    engines = {"current": jaxrod}
    wanted = args.run_engines.split(",")
    if "baseline" in wanted:
        sys.path.insert(0, args.baseline_dir)
        import jaxrod_baseline

        engines["baseline"] = jaxrod_baseline
    import jaxlib

    _say(f"  imported {', '.join(engines)} in {time.perf_counter() - t_import:.1f} s (jax {jax.__version__})")
    mem = PeakRSS()
    common = dict(case=args.case, N=args.N, side=args.side or "", engines_in_process=",".join(wanted),
                  jax_version=jax.__version__, jaxlib_version=jaxlib.__version__,
                  blas_threads=os.environ.get("OPENBLAS_NUM_THREADS", ""), cpu_count=os.cpu_count(),
                  cpu_affinity=len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else "",
                  current_src=_source_hash(os.path.dirname(jaxrod.__file__)), baseline_commit=BASELINE_COMMIT)
    if args.case == "trefoil":
        common["phi_stop_over_pi"] = round(args.phi_stop / PI, 6)
    for order, engine in enumerate(wanted, 1):
        jr = engines[engine]
        _say(f"  --- {engine} engine ({jr.__name__} from {os.path.dirname(jr.__file__)})")
        row = dict(common, engine=engine, order_in_process=order, loadavg=" ".join(f"{v:.2f}" for v in os.getloadavg()),
                   timestamp=time.strftime("%Y-%m-%d %H:%M:%S"))
        rss0 = mem.begin()
        try:
            if args.case == "michell":
                row.update(_run_michell(jr, args.N, args.verbose))
            else:
                row.update(_run_trefoil(jr, engine, args.N, args.phi_stop, args.warm and engine == "current",
                                        args.verbose))
            row["status"] = "ok"
        except Exception as exc:  # noqa: BLE001  (recorded, and the next engine still runs)
            row.update(status="error", error=f"{type(exc).__name__}: {exc}"[:300])
            _say(f"  {engine} failed: {row['error']}")
        row.update(mem.end(rss0))
        print(MARK + json.dumps(row, default=float), flush=True)


# ----------------------------------------------------------------------------------------------
# Parent: plan, run children, collect rows
# ----------------------------------------------------------------------------------------------

def _key(row):
    stop = row.get("phi_stop_over_pi", "")
    stop = "" if stop in ("", None) else f"{float(stop):.6f}"
    return (row["case"], int(row["N"]), row.get("side") or "", stop, row["engine"])


def read_rows(path):
    if not os.path.exists(path):
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def append_row(path, row):
    new = not os.path.exists(path)
    with open(path, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS, extrasaction="ignore")
        if new:
            w.writeheader()
        w.writerow({k: ("" if row.get(k) is None else row.get(k, "")) for k in FIELDS})


def drop_rows(path, keys):
    rows = [r for r in read_rows(path) if _key(r) not in keys]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow(r)


def smoke_plan():
    """The small mode's one case: a ring of 16 nodes, the current engine only, in its child process as
    at full size (a second case would only add a process start and its compilation; ``--quick`` runs
    the knot). The baseline engine is left out as in a clone without its commit: it runs the same
    loop over engines, and its cold compilation (the cache is off) would double the small run."""
    print("small mode: the baseline engine is left out", flush=True)
    return [dict(case="michell", N=16, side="", stop=None, engines=["current"], warm=False)]


def plan(args):
    if SMOKE:
        return smoke_plan()
    tasks = []
    if "michell" in args.cases:
        ns = args.michell_N or ((32, 48) if args.quick else MICHELL_NS)
        bmax = args.baseline_max_N if args.baseline_max_N is not None else (48 if args.quick else 256)
        for N in ns:
            engines = [e for e in ENGINES if e == "current" or N <= bmax]
            tasks.append(dict(case="michell", N=N, side="", stop=None, engines=engines, warm=False))
    if "trefoil" in args.cases:
        ns = args.trefoil_N or ((61,) if args.quick else TREFOIL_NS + ((TREFOIL_BIG_N,) if args.big else ()))
        sides = args.sides or (("opening",) if args.quick else tuple(SIDES))
        for N in ns:
            for side in sides:
                stop = (2.0 * PI if side == "opening" else -2.0 * PI) if args.quick else SIDES[side]
                with_baseline = not args.quick and (N <= 61 or args.baseline)
                engines = [e for e in ENGINES if e == "current" or with_baseline]
                tasks.append(dict(case="trefoil", N=N, side=side, stop=stop, engines=engines,
                                  warm=N == 61 and not args.no_warm))
    if args.engines:
        for t in tasks:
            t["engines"] = [e for e in t["engines"] if e in args.engines]
    return [t for t in tasks if t["engines"]]


def extract_baseline():
    tmp = tempfile.mkdtemp(prefix="jaxrod_baseline_")
    archive = subprocess.run(["git", "-C", REPO, "archive", BASELINE_COMMIT, "jaxrod"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
    os.rename(os.path.join(tmp, "jaxrod"), os.path.join(tmp, "jaxrod_baseline"))
    return tmp


class Clock:
    def __init__(self):
        self.t0 = time.perf_counter()

    def __call__(self, text):
        s = time.perf_counter() - self.t0
        print(f"[{int(s // 60):3d}:{s % 60:04.1f}] {text}", flush=True)


def _summary(row):
    if row.get("status") != "ok":
        return f"ERROR {row.get('error')}"
    parts = [f"first {row['first_s']:.2f} s"]
    if row.get("warm_s") not in (None, ""):
        parts.append(f"warm {row['warm_s']:.2f} s")
    if row.get("phi_star_over_pi") not in (None, ""):
        parts.append(f"phi* = {row['phi_star_over_pi']:+.8f} pi")
    else:
        parts.append(f"no branch end ({row.get('reason')})")
    if row.get("rel_error") not in (None, ""):
        parts.append(f"rel. error {row['rel_error']:.2e}")
    parts.append(f"peak RSS {row['peak_rss_mb']:.0f} MiB (+{row['peak_growth_mb']:.0f})")
    return ", ".join(parts)


def run_task(task, args, baseline_dir, csv_path, say):
    label = f"{task['case']} N={task['N']}"
    if task["side"]:
        label += f" {task['side']} (0 -> {task['stop'] / PI:+g} pi)"
    cmd = [sys.executable, os.path.abspath(__file__), "--child", "--case", task["case"], "--N", str(task["N"]),
           "--run-engines", ",".join(task["engines"]), "--baseline-dir", baseline_dir or ""]
    if task["side"]:
        cmd += ["--side", task["side"], "--phi-stop", repr(task["stop"])]
    if task["warm"]:
        cmd.append("--warm")
    if args.verbose:
        cmd.append("--verbose")
    say(f"{label}: {' then '.join(task['engines'])} (child process)")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1, cwd=REPO)
    timer = None
    if args.timeout:
        timer = threading.Timer(args.timeout, proc.kill)
        timer.start()
    got = []
    try:
        for line in proc.stdout:
            line = line.rstrip("\n")
            if line.startswith(MARK):
                row = json.loads(line[len(MARK):])
                append_row(csv_path, row)
                got.append(row["engine"])
                say(f"{label} {row['engine']}: {_summary(row)}")
            elif line.strip():
                say("  |" + line)
        proc.wait()
    except KeyboardInterrupt:
        proc.kill()
        proc.wait()
        raise
    finally:
        if timer is not None:
            timer.cancel()
    missing = [e for e in task["engines"] if e not in got]
    if missing:
        say(f"{label}: no result for {', '.join(missing)} (child exit status {proc.returncode}"
            f"{', timed out' if args.timeout and proc.returncode == -9 else ''})")


# ----------------------------------------------------------------------------------------------
# Report
# ----------------------------------------------------------------------------------------------

def _f(row, k):
    v = row.get(k, "") if row else ""
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def _s(v, fmt):
    return "" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def _ratio(a, b):
    return f"{a / b:.1f}x" if a is not None and b not in (None, 0.0) else ""


def _fit(points):
    """Slope of log t against log N over the largest three N (fewer if fewer)."""
    import numpy as np

    pts = sorted(points)[-3:]
    if len(pts) < 2:
        return None, pts
    slope = np.polyfit(np.log([p[0] for p in pts]), np.log([p[1] for p in pts]), 1)[0]
    return float(slope), pts


def _machine(rows):
    info = [f"{platform.machine()}, {platform.system()} {platform.release()}, Python {platform.python_version()}"]
    try:
        with open("/proc/cpuinfo") as f:
            model = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), "")
        if model:
            info.append(model)
    except OSError:
        pass
    last = rows[-1] if rows else {}
    info.append(f"{last.get('cpu_count', os.cpu_count())} CPUs (usable by the process: "
                f"{last.get('cpu_affinity', '')})")
    info.append(f"jax {last.get('jax_version', '')}, jaxlib {last.get('jaxlib_version', '')}, "
                f"BLAS threads (OPENBLAS_NUM_THREADS) {last.get('blas_threads', '')}")
    loads = [r["loadavg"].split()[0] for r in rows if r.get("loadavg")]
    if loads:
        info.append(f"1-min load average at the start of each run: {min(loads, key=float)} to {max(loads, key=float)}")
    return info


def _git_rev():
    try:
        rev = subprocess.run(["git", "-C", REPO, "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                             check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", REPO, "status", "--porcelain", "--", "jaxrod"], capture_output=True,
                               text=True, check=True).stdout.strip()
        return rev + (" + uncommitted changes in jaxrod/" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def write_report(csv_path, md_path, png_path):
    rows = read_rows(csv_path)
    latest = {}
    for r in rows:
        latest[_key(r)] = r
    rows = list(latest.values())
    ok = [r for r in rows if r.get("status") == "ok"]
    mich = {(int(r["N"]), r["engine"]): r for r in ok if r["case"] == "michell"}
    tref = {}
    for r in ok:
        if r["case"] == "trefoil":
            tref[(int(r["N"]), r["side"], float(r["phi_stop_over_pi"]), r["engine"])] = r
    img = os.path.relpath(png_path, os.path.dirname(os.path.abspath(md_path)))
    L = ["# jaxrod speed: current engine against the baseline", "",
         f"Baseline: the code of commit {BASELINE_COMMIT} (dense `jax.hessian` everywhere, full `eigh`, "
         "continuation branch ends located by bisection). Current: the working tree "
         f"(`jaxrod/` at {_git_rev()} when this report was written; "
         "the source hash of each run is in `speed.csv`, column `current_src`). Same problems, same tolerances, "
         "same process. Generated by `python benchmarks/speed.py` from `speed.csv`.", "", provenance_line(), ""]
    L += ["## Machine", ""] + [f"- {x}" for x in _machine(rows)] + [""]

    if mich:
        analytic = michell_analytic()
        L += ["## Michell's ring: critical twist", "",
              f"`critical_twist(michell_ring(N, 0.5), 0, 2 phi_a, ContinuationOptions(step=phi_a/8, tol=1e-6 pi))`, "
              f"phi_a = 2 pi sqrt(3) (1 + nu) = {analytic / PI:.10f} pi. 'first': first call, JIT compilation "
              "included; 'warm': the second call in the same process. Ratios are baseline / current.", "",
              "| N | current first (s) | current warm (s) | baseline first (s) | baseline warm (s) | ratio first | "
              "ratio warm | current phi*/pi | baseline phi*/pi | difference (pi) | current rel. error | "
              "baseline rel. error | evals current / baseline |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for N in sorted({n for n, _ in mich}):
            c, b = mich.get((N, "current")), mich.get((N, "baseline"))
            cp, bp = _f(c, "phi_star_over_pi"), _f(b, "phi_star_over_pi")
            diff = f"{cp - bp:+.1e}" if cp is not None and bp is not None else ""
            ev = f"{c['evals'] if c else ''} / {b['evals'] if b else ''}"
            L.append(f"| {N} | {_s(_f(c, 'first_s'), '.2f')} | {_s(_f(c, 'warm_s'), '.3f')} | "
                     f"{_s(_f(b, 'first_s'), '.2f')} | {_s(_f(b, 'warm_s'), '.3f')} | "
                     f"{_ratio(_f(b, 'first_s'), _f(c, 'first_s'))} | {_ratio(_f(b, 'warm_s'), _f(c, 'warm_s'))} | "
                     f"{_s(cp, '.10f')} | {_s(bp, '.10f')} | {diff} | {_s(_f(c, 'rel_error'), '.3e')} | "
                     f"{_s(_f(b, 'rel_error'), '.3e')} | {ev} |")
        L += ["", "Cost growth, warm time ~ N^p (least squares on log t against log N over the largest three N "
              "measured for that engine; local exponents between successive N in brackets):", ""]
        for engine in ENGINES:
            pts = sorted((n, float(r["warm_s"])) for (n, e), r in mich.items() if e == engine)
            p, used = _fit(pts)
            if p is None:
                continue
            local = ", ".join(f"{math.log(t2 / t1) / math.log(n2 / n1):.2f}"
                              for (n1, t1), (n2, t2) in zip(pts, pts[1:]))
            L.append(f"- {engine}: p = {p:.2f} over N = {', '.join(str(n) for n, _ in used)} ({local})")
        L += ["", "'evals': equilibria with a spectrum, scan steps plus refinement evaluations. "
              "'difference': current minus baseline phi*; both locate phi* to 1e-6 pi.", ""]

    if tref:
        L += ["## Trefoil: branch ends", "",
              f"Trefoil (D, L) = ({TREFOIL_D:g}, {TREFOIL_L:g}) mm, nu = 0.5, relaxed at phi = 0, then "
              f"`follow_twist(..., ContinuationOptions(step=0.5 pi, tol=2e-4 pi, switch=False))` to the first branch end, one side at a "
              "time (opening: phi > 0; tightening: phi < 0). Time = relax + follow, first run in its process "
              "(compilation included). Steps: accepted continuation steps (bisection steps included). "
              "Ratios are baseline / current.", "",
              "| N | side (range) | current time (s) | of it relax (s) | baseline time (s) | of it relax (s) | "
              "ratio time | ratio follow | current phi*/pi | baseline phi*/pi | difference (pi) | "
              "phi_error current / baseline (pi) | steps current / baseline |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        groups = sorted({k[:3] for k in tref}, key=lambda k: (k[0], k[1] != "opening", k[2]))
        for N, side, stop in groups:
            c, b = tref.get((N, side, stop, "current")), tref.get((N, side, stop, "baseline"))
            cp, bp = _f(c, "phi_star_over_pi"), _f(b, "phi_star_over_pi")
            diff = f"{cp - bp:+.1e}" if cp is not None and bp is not None else ""

            def phi_text(r, v):
                return "" if r is None else (f"{v:+.6f}" if v is not None else "none")

            def err(r):
                v = _f(r, "phi_error")
                return "" if v is None else f"{v / PI:.1e}"

            L.append(f"| {N} | {side} (0 -> {stop:+g} pi) | {_s(_f(c, 'first_s'), '.1f')} | "
                     f"{_s(_f(c, 'relax_s'), '.1f')} | {_s(_f(b, 'first_s'), '.1f')} | {_s(_f(b, 'relax_s'), '.1f')} | "
                     f"{_ratio(_f(b, 'first_s'), _f(c, 'first_s'))} | {_ratio(_f(b, 'follow_s'), _f(c, 'follow_s'))} | "
                     f"{phi_text(c, cp)} | {phi_text(b, bp)} | {diff} | {err(c)} / {err(b)} | "
                     f"{c['steps'] if c else ''} / {b['steps'] if b else ''} |")
        warm = [(k, r) for k, r in tref.items() if _f(r, "warm_s") is not None]
        if warm:
            L += ["", "Compilation, current engine: the same case run twice in one process; "
                  "compile = cold - warm.", "",
                  "| N | side | cold relax (s) | warm relax (s) | cold follow (s) | warm follow (s) | "
                  "cold total (s) | warm total (s) | compile (s) |", "|---|---|---|---|---|---|---|---|---|"]
            for (N, side, stop, _), r in sorted(warm, key=lambda kr: (kr[0][0], kr[0][1] != "opening")):
                L.append(f"| {N} | {side} (0 -> {stop:+g} pi) | {_s(_f(r, 'relax_s'), '.1f')} | "
                         f"{_s(_f(r, 'warm_relax_s'), '.1f')} | {_s(_f(r, 'follow_s'), '.1f')} | "
                         f"{_s(_f(r, 'warm_follow_s'), '.1f')} | {_s(_f(r, 'first_s'), '.1f')} | "
                         f"{_s(_f(r, 'warm_s'), '.1f')} | {_s(_f(r, 'compile_s'), '.1f')} |")
        L.append("")

    if ok:
        L += ["## Peak memory", "",
              "Resident memory of the child process during each engine's run: peak (high-water mark) and "
              "growth over the resident memory at that engine's start (which holds Python, JAX, both packages, "
              "and whatever the engine run before it in the process left behind).", "",
              "| case | N | side | current peak (MiB) | current growth | baseline peak (MiB) | baseline growth |",
              "|---|---|---|---|---|---|---|"]
        cases = sorted({(r["case"], int(r["N"]), r["side"] or "", r.get("phi_stop_over_pi", "")) for r in ok},
                       key=lambda k: (k[0], k[1], k[2] != "opening"))
        for case, N, side, stop in cases:
            by = {r["engine"]: r for r in ok if (r["case"], int(r["N"]), r["side"] or "", r.get("phi_stop_over_pi", ""))
                  == (case, N, side, stop)}
            c, b = by.get("current"), by.get("baseline")
            L.append(f"| {case} | {N} | {side} | {_s(_f(c, 'peak_rss_mb'), '.0f')} | "
                     f"{_s(_f(c, 'peak_growth_mb'), '+.0f')} | {_s(_f(b, 'peak_rss_mb'), '.0f')} | "
                     f"{_s(_f(b, 'peak_growth_mb'), '+.0f')} |")
        methods = sorted({r.get("rss_method", "") for r in ok})
        L += ["", f"Measured as: {'; '.join(methods)}.", ""]

    errors = [r for r in rows if r.get("status") != "ok"]
    srcs = sorted({r.get("current_src", "") for r in ok if r["engine"] == "current"})
    L += ["## How this was measured", "",
          "- Each (case, N, side) runs in its own child process of `benchmarks/speed.py`, which imports the "
          "working tree's `jaxrod` first (float64, single-threaded BLAS), then `jaxrod_baseline`: the `jaxrod/` "
          f"folder of {BASELINE_COMMIT} from `git archive`, renamed (it uses relative imports only). It runs the "
          "current engine and then the baseline on the same problem and prints one result per engine. The "
          "parent appends each as a row of `speed.csv` as it arrives. A fresh process per case keeps the JIT "
          "caches and the memory of one case out of the next. Both engines of a case share one process, so "
          "they run on the same JAX, the same BLAS settings and the same machine load.",
          "- The current engine runs first. JAX's one-time costs in a process (backend start, compiling the "
          "small eager operations both packages use) therefore fall on the current engine's first call, not "
          "the baseline's: the 'first' ratios understate the current engine's gain, if anything. No persistent "
          "compilation cache is used, so every first call compiles.",
          "- Peak memory per engine: before each engine starts, the process's resident high-water mark is "
          "reset (`/proc/self/clear_refs`, Linux) and read (VmHWM) after it ends, so each engine's peak is its "
          "own even though both share the process. `ru_maxrss` of a process cannot be reset, which is why it "
          "is not used for the second engine (it is kept in the CSV as `process_maxrss_mb`).",
          "- Times are wall-clock (`time.perf_counter`) on a shared machine: other jobs may have used the cores; "
          "the load average at the start of each run is in the CSV.",
          ""]
    if len(srcs) > 1:
        L += [f"Warning: the rows come from {len(srcs)} different versions of the current engine's source "
              f"({', '.join(srcs)}).", ""]
    if errors:
        L += ["Runs that failed (rerun to retry):", ""]
        L += [f"- {' '.join(v for v in (r['case'], 'N=' + r['N'], r['side'], r['engine']) if v)}: {r.get('error', '')}"
              for r in errors] + [""]
    L += [f"![speed]({img})", ""]
    # The README's command 1 against the previous release: measured by benchmarks/command1.py.
    # And the issue-9 comparisons: damped dynamics against continuation at equal accuracy
    # (benchmarks/dynamics_accuracy.py) and batched (vmap) against serial runs (benchmarks/batch.py);
    # command 1 as two CLI processes (benchmarks/cli_start.py) and where its time goes
    # (benchmarks/cli_startup_breakdown.py).
    for name in ("command1.md", "cli_start.md", "cli_startup_breakdown.md", "dynamics_accuracy.md", "batch.md"):
        part = os.path.join(results_dir(), name)
        if os.path.exists(part):
            with open(part) as f:
                L += ["\n".join("#" + line if line.startswith("#") else line for line in f.read().strip().splitlines()), ""]
    os.makedirs(os.path.dirname(os.path.abspath(md_path)), exist_ok=True)
    with open(md_path, "w") as f:
        f.write("\n".join(L))
    plot(mich, tref, png_path)
    return "\n".join(L)


def plot(mich, tref, png_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    import numpy as np

    panels = int(bool(mich)) + int(bool(tref))
    if not panels:
        return
    fig, axes = plt.subplots(1, panels, figsize=(6.2 * panels, 4.6), squeeze=False)
    axes = list(axes[0])
    colours = {"current": "C0", "baseline": "C3"}
    if mich:
        ax = axes.pop(0)
        for engine in ENGINES:
            pts = sorted((n, r) for (n, e), r in mich.items() if e == engine)
            if not pts:
                continue
            ns = [n for n, _ in pts]
            warm = [float(r["warm_s"]) for _, r in pts]
            first = [float(r["first_s"]) for _, r in pts]
            p, _ = _fit(list(zip(ns, warm)))
            slope = f", slope {p:.2f}" if p is not None else ""
            ax.loglog(ns, warm, "o-", color=colours[engine], label=f"{engine}, warm{slope}")
            ax.loglog(ns, first, "s--", color=colours[engine], mfc="none", alpha=0.6,
                      label=f"{engine}, first call (compile incl.)")
        all_ns = sorted({n for n, _ in mich})
        ax.set_xticks(all_ns)
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("N (nodes)")
        ax.set_ylabel("time to phi* (s)")
        ax.set_title("Michell ring: critical twist to 1e-6 pi")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    if tref:
        ax = axes.pop(0)
        groups = sorted({k[:3] for k in tref}, key=lambda k: (k[0], k[1] != "opening", k[2]))
        # Per group: baseline, current (first run in the process), current warm where measured.
        bars = [("baseline", "first_s", "relax_s", "baseline", None),
                ("current", "first_s", "relax_s", "current", None),
                ("current", "warm_s", "warm_relax_s", "current, warm (second run)", "//")]
        width = 0.8 / len(bars)
        labelled, values = set(), []
        for j, g in enumerate(groups):
            for i, (engine, key, relax_key, label, hatch) in enumerate(bars):
                r = tref.get(g + (engine,))
                total, relax = _f(r, key), _f(r, relax_key)
                if total is None:
                    continue
                x = j + (i - (len(bars) - 1) / 2) * width
                ax.bar(x, total, width, color=colours[engine], alpha=0.5 if hatch else 0.85, hatch=hatch,
                       edgecolor="k" if hatch else None, linewidth=0.5,
                       label=None if label in labelled else f"{label}: relax + follow")
                labelled.add(label)
                values.append(total)
                if relax is not None:
                    ax.bar(x, relax, width * 0.45, color="k", alpha=0.4,
                           label=None if "relax" in labelled else "of it: relax at phi = 0")
                    labelled.add("relax")
                    values.append(relax)
                ax.annotate(f"{total:.0f} s" if total >= 10 else f"{total:.2g} s", (x, total), ha="center",
                            va="bottom", fontsize=7)
        ax.set_xticks(np.arange(len(groups)))
        ax.set_xticklabels([f"N={n}\n{side}\n0 -> {stop:+g} pi" for n, side, stop in groups], fontsize=8)
        ax.set_xlim(-0.6, len(groups) - 0.4)
        ax.set_yscale("log")
        positive = [v for v in values if v > 0]
        if positive:
            ax.set_ylim(min(positive) / 2.0, max(positive) * 3.0)
        ax.set_ylabel("wall time (s)")
        ax.set_title("Trefoil (8, 292): one branch end per side")
        ax.grid(True, axis="y", which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(png_path)), exist_ok=True)
    fig.savefig(png_path, dpi=130)
    plt.close(fig)


# ----------------------------------------------------------------------------------------------

def parse(argv=None):
    p = argparse.ArgumentParser(description="Speed of the current jaxrod engine against the baseline (61e87f5).",
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog=__doc__.split("\n\n", 1)[1])
    p.add_argument("--cases", nargs="+", choices=("michell", "trefoil"), default=["michell", "trefoil"])
    p.add_argument("--michell-N", type=int, nargs="+", help="ring sizes (default 64 128 256 512 1024)")
    p.add_argument("--baseline-max-N", type=int, help="largest ring for the baseline (default 256)")
    p.add_argument("--trefoil-N", type=int, nargs="+", help="knot sizes (default 61 121, + 241 with --big)")
    p.add_argument("--sides", nargs="+", choices=tuple(SIDES), help="trefoil sides (default both)")
    p.add_argument("--big", action="store_true", help="trefoil N = 241 too")
    p.add_argument("--baseline", action="store_true", help="run the baseline on trefoils with N > 61 too")
    p.add_argument("--engines", nargs="+", choices=ENGINES, help="run only these engines")
    p.add_argument("--no-warm", action="store_true", help="skip the second (warm) trefoil run at N = 61")
    p.add_argument("--quick", action="store_true",
                   help="tiny versions for testing: Michell N = 32, 48 (both engines); trefoil N = 61, opening "
                        "side 0 -> 2 pi, current engine only; output into a temporary folder unless --out")
    p.add_argument("--out", help="output folder (default benchmarks/results/)")
    p.add_argument("--md-path", help="where to write the Markdown report (default OUT/BENCHMARKS.md)")
    p.add_argument("--force", action="store_true", help="rerun cases whose rows are already in speed.csv")
    p.add_argument("--report-only", action="store_true", help="only write BENCHMARKS.md and speed.png")
    p.add_argument("--timeout", type=float, help="seconds allowed per child process (default: none)")
    p.add_argument("--verbose", action="store_true", help="show critical_twist's scan lines too (Michell)")
    # child mode (internal)
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--case", help=argparse.SUPPRESS)
    p.add_argument("--N", type=int, help=argparse.SUPPRESS)
    p.add_argument("--side", help=argparse.SUPPRESS)
    p.add_argument("--phi-stop", type=float, help=argparse.SUPPRESS)
    p.add_argument("--warm", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--run-engines", help=argparse.SUPPRESS)
    p.add_argument("--baseline-dir", help=argparse.SUPPRESS)
    return p.parse_args(argv)


def main(argv=None):
    args = parse(argv)
    if args.child:
        child(args)
        return
    out = args.out or (os.path.join(tempfile.gettempdir(), "jaxrod_speed_quick") if args.quick
                       else results_dir())
    os.makedirs(out, exist_ok=True)
    csv_path = os.path.join(out, "speed.csv")
    md_path = args.md_path or os.path.join(out, "BENCHMARKS.md")
    png_path = os.path.join(out, "speed.png")
    say = Clock()
    if not args.report_only:
        tasks = plan(args)
        done = {_key(r) for r in read_rows(csv_path) if r.get("status") == "ok"}
        baseline_dir = None
        say(f"{len(tasks)} cases, results into {csv_path}")
        try:
            for task in tasks:
                stop = "" if task["stop"] is None else f"{round(task['stop'] / PI, 6):.6f}"
                keys = {e: (task["case"], task["N"], task["side"], stop, e) for e in task["engines"]}
                if args.force:
                    if os.path.exists(csv_path):
                        drop_rows(csv_path, set(keys.values()))
                else:
                    skipped = [e for e in task["engines"] if keys[e] in done]
                    task["engines"] = [e for e in task["engines"] if keys[e] not in done]
                    if skipped:
                        name = f"{task['case']} N={task['N']}" + (f" {task['side']}" if task["side"] else "")
                        say(f"{name}: {', '.join(skipped)} already in "
                            "speed.csv, skipped (--force to rerun)")
                    if not task["engines"]:
                        continue
                if "baseline" in task["engines"] and baseline_dir is None:
                    baseline_dir = extract_baseline()
                    say(f"baseline {BASELINE_COMMIT} extracted to {baseline_dir}/jaxrod_baseline")
                run_task(task, args, baseline_dir, csv_path, say)
        finally:
            if baseline_dir is not None:
                shutil.rmtree(baseline_dir, ignore_errors=True)
    if not os.path.exists(csv_path):
        say(f"no results in {csv_path}")
        return
    write_report(csv_path, md_path, png_path)
    say(f"wrote {md_path} and {png_path}")


if __name__ == "__main__":
    main()
