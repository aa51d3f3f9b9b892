"""Every script in benchmarks/ runs in its small mode and writes its files: the second half
(see test_benchmarks_smoke_a.py)."""
import importlib.util
import pathlib

import pytest

_PATH = pathlib.Path(__file__).resolve().parent.parent / "benchmarks" / "_smoke.py"
_spec = importlib.util.spec_from_file_location("benchmarks_smoke", _PATH)
smoke = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(smoke)

GROUP = "b"


def check_script(script, tmp_path):
    code, seconds, output = smoke.run(script, tmp_path)
    print(f"{script}: {seconds:.1f} s")
    assert code == 0, f"{script} failed (exit {code}) after {seconds:.1f} s:\n{output[-4000:]}"
    missing = smoke.missing_outputs(script, tmp_path)
    assert not missing, f"{script} did not write {missing}:\n{output[-2000:]}"


@pytest.mark.parametrize("script", sorted(s for s, e in smoke.SCRIPTS.items() if e["group"] == GROUP))
def test_script_runs_small(script, tmp_path):
    check_script(script, tmp_path)
