"""docs/getting-started.md runs as written, top to bottom, and its results are right: the trefoil's
ends are those of the newcomer's tasks, Michell's ring approaches 2 pi sqrt(3) (1 + nu) at second
order and its sensitivity to nu is phi* / (1 + nu)."""
import math
import pathlib
import re

import pytest

PAGE = pathlib.Path(__file__).resolve().parent.parent / "docs" / "getting-started.md"


@pytest.fixture(scope="module")
def page():
    namespace = {"__name__": "getting_started"}
    for block in re.findall(r"^```python\n(.*?)^```", PAGE.read_text(), flags=re.S | re.M):
        exec(compile(block, str(PAGE), "exec"), namespace)
    return namespace


def test_the_page_has_the_six_tasks():
    assert len(re.findall(r"^```python\n", PAGE.read_text(), flags=re.M)) == 6


def test_the_trefoil_ends(page):
    plus, minus = page["ends"]
    assert plus.phi / math.pi == pytest.approx(6.601, abs=2e-3)
    assert minus.phi / math.pi == pytest.approx(-11.475, abs=2e-3)


def test_the_continuation_recorded_every_point(page):
    assert page["path"].completed and len(page["writhe"]) == len(page["path"].points) >= 3


def test_michell(page):
    rel = (page["plus"].phi - page["analytic"]) / page["analytic"]
    assert 20.0 / 60 ** 2 < rel < 40.0 / 60 ** 2
    assert page["slope"] == pytest.approx(page["plus"].phi / 1.5, rel=1e-6)
