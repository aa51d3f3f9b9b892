"""Every public name (jaxrod.__all__) has a numpy-style docstring; every public function's says what
it returns and what it raises (``Returns`` and ``Raises`` sections)."""
import inspect
import re

import pytest

import jaxrod as jr


def _sections(doc):
    # a numpy section: a title line underlined by dashes
    return set(re.findall(r"^\s*(\w[\w ]*)\n\s*-{3,}\s*$", doc or "", flags=re.M))


@pytest.mark.parametrize("name", jr.__all__)
def test_public_name_has_a_docstring(name):
    obj = getattr(jr, name)
    doc = inspect.getdoc(obj)
    assert doc and len(doc.split()) >= 5, name


@pytest.mark.parametrize("name", [n for n in jr.__all__ if inspect.isfunction(getattr(jr, n))])
def test_public_function_says_what_it_returns_and_raises(name):
    sections = _sections(inspect.getdoc(getattr(jr, name)))
    assert {"Returns", "Raises"} <= sections, (name, sections)
