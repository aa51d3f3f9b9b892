"""Every script in benchmarks/ runs in its small mode and writes its files (first half; the second
half is test_benchmarks_smoke_b.py, so that the suite's two workers share them)."""
import importlib.util
import pathlib

import pytest

_PATH = pathlib.Path(__file__).resolve().parent.parent / "benchmarks" / "_smoke.py"
_spec = importlib.util.spec_from_file_location("benchmarks_smoke", _PATH)
smoke = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(smoke)

GROUP = "a"


def check_script(script, tmp_path):
    code, seconds, output = smoke.run(script, tmp_path)
    print(f"{script}: {seconds:.1f} s")
    assert code == 0, f"{script} failed (exit {code}) after {seconds:.1f} s:\n{output[-4000:]}"
    missing = smoke.missing_outputs(script, tmp_path)
    assert not missing, f"{script} did not write {missing}:\n{output[-2000:]}"


@pytest.mark.parametrize("script", sorted(s for s, e in smoke.SCRIPTS.items() if e["group"] == GROUP))
def test_script_runs_small(script, tmp_path):
    check_script(script, tmp_path)


def test_every_script_is_run_or_excused():
    listed = set(smoke.SCRIPTS) | set(smoke.NO_SMOKE)
    present = set(smoke.all_scripts())
    assert present - listed == set(), "benchmark scripts with neither a smoke run nor a reason"
    assert listed - present == set(), "smoke entries for scripts that are gone"
    assert not set(smoke.SCRIPTS) & set(smoke.NO_SMOKE)
    for script, reason in sorted(smoke.NO_SMOKE.items()):
        print(f"not run in the smoke test: {script}: {reason}")
