"""The generated parts of the docs site: the CLI reference covers every command, the Validation
table has a row read from a result file for each reference, every chart a page shows is added to
the site, and every page in the navigation exists. (The build itself, `mkdocs build --strict`, runs
in .ci/run.)"""
import importlib.util
import pathlib
import re

import pytest

pytest.importorskip("mkdocs")  # the docs extra

REPO = pathlib.Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"


@pytest.fixture(scope="module")
def hook():
    spec = importlib.util.spec_from_file_location("gen_pages", DOCS / "gen_pages.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_cli_reference_has_every_command(hook):
    from jaxrod.cli.parser import COMMANDS

    page = hook.cli_reference()
    for name in COMMANDS:
        assert f"## jaxrod {name}\n" in page, name
    assert "usage: jaxrod trefoil" in page and "--phi-min" in page


def test_every_validation_row_comes_from_a_result_file(hook):
    rows = [line for line in hook.validation_table().splitlines()[2:]]
    for reference in ("Michell", "Greenhill", "tightening side", "opening side", "Neukirch", "PyElastica"):
        row = next((r for r in rows if reference in r), None)
        assert row is not None and "no result file" not in row and "`" in row.split("|")[-2], reference


def test_the_generated_tables_have_rows(hook):
    for make in (hook.performance_table, hook.speed_table, hook.sparse_contact_table, hook.dynamics_table,
                 hook.peer_table, hook.per_step_table, hook.compile_table):
        table = make()
        assert table.startswith("|") and len(table.splitlines()) > 3, make.__name__


def test_every_marker_has_a_generator_and_every_chart_is_added(hook):
    for page in DOCS.rglob("*.md"):
        text = page.read_text()
        for name in re.findall(r"<!-- generated: (\w+) -->", text):
            assert name in hook.GENERATORS, (page.name, name)
        for chart in re.findall(r"\]\((?:\.\./)?results/([\w.]+\.png)\)", text):
            assert chart in hook.CHARTS and (hook.RESULTS / chart).exists(), (page.name, chart)


def test_every_page_in_the_navigation_exists():
    config = (REPO / "mkdocs.yml").read_text()
    pages = re.findall(r":\s+([\w/.-]+\.(?:md|ipynb))\s*$", config, flags=re.M)
    assert len(pages) >= 20
    for page in pages:
        assert (DOCS / page).exists(), page


def test_the_loose_limit_table_is_rebuilt_from_its_json(hook):
    import json
    import math

    data = json.loads((hook.RESULTS / "loose_limit.json").read_text())
    table = hook.loose_limit_table()
    assert len(table.splitlines()) == 2 + len(data["rows"]) + 2  # header, rule, a row per point, the command
    for r in data["rows"]:
        assert f"{r['phi_star'] / math.pi:+.4f} π ± {r['error'] / math.pi:.1e} π" in table, r
    assert data["provenance"]["command"] in table
