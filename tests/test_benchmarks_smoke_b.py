"""Every script in benchmarks/ runs in its small mode and writes its files: the second half
(see test_benchmarks_smoke_a.py)."""
import pytest
from test_benchmarks_smoke_a import check_script, group_scripts, run_group

# Run with -m smoke (pyproject.toml: the tiers).
pytestmark = pytest.mark.smoke

GROUP = "b"


@pytest.fixture(scope="module")
def shared_results(tmp_path_factory):
    return run_group(GROUP, tmp_path_factory)


@pytest.mark.parametrize("script", group_scripts(GROUP))
def test_script_runs_small(script, shared_results, tmp_path):
    check_script(script, shared_results, tmp_path)
