"""Every script in benchmarks/ runs in its small mode and writes its files: the second half
(see test_benchmarks_smoke_a.py)."""
import pytest
from test_benchmarks_smoke_a import check_script, smoke

GROUP = "b"


@pytest.mark.parametrize("script", sorted(s for s, e in smoke.SCRIPTS.items() if e["group"] == GROUP))
def test_script_runs_small(script, tmp_path):
    check_script(script, tmp_path)
