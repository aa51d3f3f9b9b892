"""Every script in benchmarks/ runs in its small mode and writes its files, each results file with
its provenance (first half; the second half is test_benchmarks_smoke_b.py, so that the suite's two
workers share them). A group's scripts run one after another in one process (``_smoke.run_many``),
those in ``_smoke.OWN_PROCESS`` each in its own."""
import importlib.util
import json
import pathlib

import pytest

# Run with -m smoke (pyproject.toml: the tiers).
pytestmark = pytest.mark.smoke

_PATH = pathlib.Path(__file__).resolve().parent.parent / "benchmarks" / "_smoke.py"
_spec = importlib.util.spec_from_file_location("benchmarks_smoke", _PATH)
smoke = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(smoke)

GROUP = "a"


def group_scripts(group):
    return sorted(s for s, e in smoke.SCRIPTS.items() if e["group"] == group)


def run_group(group, tmp_path_factory):
    """The group's shared-process scripts, run once for the test file: {script: (code, seconds, output, out)}."""
    root = tmp_path_factory.mktemp(f"smoke_{group}")
    shared = [s for s in group_scripts(group) if s not in smoke.OWN_PROCESS]
    return {s: (*r, root / s[:-3]) for s, r in smoke.run_many(shared, root).items()}


def missing_provenance(out):
    """The .md and .json files under ``out`` that do not record the commit and command that wrote them."""
    bad = []
    for path in sorted(out.iterdir()):
        if path.suffix == ".md" and "Produced by `python " not in path.read_text():
            bad.append(path.name)
        if path.suffix == ".json":
            data = json.loads(path.read_text())
            prov = data.get("provenance") if isinstance(data, dict) else None
            if not (isinstance(prov, dict) and prov.get("commit") and prov.get("command")):
                bad.append(path.name)
    return bad


def check_script(script, shared_results, tmp_path):
    if script in shared_results:
        code, seconds, output, out = shared_results[script]
    else:
        (code, seconds, output), out = smoke.run(script, tmp_path), tmp_path
    print(f"{script}: {seconds:.1f} s")
    assert code == 0, f"{script} failed (exit {code}) after {seconds:.1f} s:\n{output[-4000:]}"
    missing = smoke.missing_outputs(script, out)
    assert not missing, f"{script} did not write {missing}:\n{output[-2000:]}"
    unmarked = missing_provenance(out)
    assert not unmarked, f"{script} wrote {unmarked} without its commit and command"


@pytest.fixture(scope="module")
def shared_results(tmp_path_factory):
    return run_group(GROUP, tmp_path_factory)


@pytest.mark.parametrize("script", group_scripts(GROUP))
def test_script_runs_small(script, shared_results, tmp_path):
    check_script(script, shared_results, tmp_path)


def test_every_script_is_run_or_excused():
    listed = set(smoke.SCRIPTS) | set(smoke.NO_SMOKE)
    present = set(smoke.all_scripts())
    assert present - listed == set(), "benchmark scripts with neither a smoke run nor a reason"
    assert listed - present == set(), "smoke entries for scripts that are gone"
    assert not set(smoke.SCRIPTS) & set(smoke.NO_SMOKE)
    assert set(smoke.OWN_PROCESS) <= set(smoke.SCRIPTS)
    for script, reason in sorted(smoke.NO_SMOKE.items()):
        print(f"not run in the smoke test: {script}: {reason}")
    for script, reason in sorted(smoke.OWN_PROCESS.items()):
        print(f"run in a process of its own: {script}: {reason}")
