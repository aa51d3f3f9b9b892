"""Every ```python block of the documentation pages runs: the blocks of one page in order, in one
namespace, in a temporary folder. Pages whose blocks a test of their own runs (and checks the
results of) are listed in OWN_TEST and skipped here, after checking that test exists."""
import pathlib
import re
import warnings

import pytest

REPO = pathlib.Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"
OWN_TEST = {"getting-started.md": "test_newcomer.py", "extending.md": "test_extending.py",
            "guides/differentiable.md": "test_differentiable.py"}
PAGES = sorted(p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md"))


def python_blocks(text):
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def test_pages_with_their_own_test_have_it():
    for page, test in OWN_TEST.items():
        assert (DOCS / page).exists() and (REPO / "tests" / test).exists(), (page, test)
        assert f'"{page}"' in (REPO / "tests" / test).read_text(), (page, test)


def test_every_python_block_is_marked_python():
    # a block fenced as ```py or ```Python would escape this test
    for page in PAGES:
        fences = re.findall(r"^```(\w[\w-]*)", (DOCS / page).read_text(), flags=re.M)
        assert not {f for f in fences if f.lower() in ("py", "python3", "pycon") or f == "Python"}, page


# The shear guide's examples follow Cosserat rings and knots for ~20 s: the validation tier
# (-m validation) runs them.
LONG_PAGES = ("guides/shear.md",)


@pytest.mark.parametrize("page", [pytest.param(p, marks=pytest.mark.validation) if p in LONG_PAGES else p
                                  for p in PAGES if p not in OWN_TEST and python_blocks((DOCS / p).read_text())])
def test_page_python_blocks_run(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": f"docs_{page}"}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a page's example runs without a warning
        blocks = python_blocks((DOCS / page).read_text())
        for number, block in enumerate(blocks):
            exec(compile(block, f"docs/{page} python block {number}", "exec"), namespace)
    assert blocks and len(namespace) > 2  # the page has code, and its code defined names
