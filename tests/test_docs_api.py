"""The public API is documented where mkdocstrings reads it: every name in ``jaxrod.__all__`` and the
continuation engine's entry has a numpy-style docstring, functions with ``Parameters``, ``Returns``
and ``Raises`` sections, classes that take parameters with ``Parameters`` or ``Attributes``."""
import inspect
import re

import pytest

import jaxrod
import jaxrod.continuation as continuation_pkg

ENGINE_NAMES = ("continuation", "TwistProblem", "StableOnly", "PseudoArclength")


def _public():
    named = [(f"jaxrod.{n}", getattr(jaxrod, n)) for n in jaxrod.__all__]
    named += [(f"jaxrod.continuation.{n}", getattr(continuation_pkg, n)) for n in ENGINE_NAMES]
    return named


def _sections(doc):
    """Numpy section headers: a title line followed by a line of dashes of at least its length."""
    lines = doc.splitlines()
    return {lines[i].strip() for i in range(len(lines) - 1)
            if lines[i].strip() and re.fullmatch(r"-{3,}", lines[i + 1].strip())
            and len(lines[i + 1].strip()) >= len(lines[i].strip())}


def _takes_parameters(cls):
    try:
        params = inspect.signature(cls).parameters
    except (TypeError, ValueError):  # enums and builtins: their members are their attributes
        return True
    return any(p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD) for p in params.values())


def _missing(obj):
    doc = inspect.getdoc(obj) or ""
    if not doc.strip():
        return ["a docstring"]
    summary = doc.strip().splitlines()[0]
    found = _sections(doc)
    missing = [] if summary and not set(summary) <= set("-") else ["a summary line"]
    if inspect.isclass(obj):
        if _takes_parameters(obj) and not found & {"Parameters", "Attributes"}:
            missing.append("a 'Parameters' or 'Attributes' section")
    else:
        missing += [f"a '{s}' section" for s in ("Parameters", "Returns", "Raises") if s not in found]
    return missing


def test_names_are_the_documented_surface():
    names = {n for n, _ in _public()}
    assert len(names) == len(jaxrod.__all__) + len(ENGINE_NAMES)
    for name, obj in _public():
        assert callable(obj), f"{name} is not a function or class"


@pytest.mark.parametrize("name,obj", _public(), ids=[n for n, _ in _public()])
def test_public_name_has_numpy_docstring(name, obj):
    missing = _missing(obj)
    assert not missing, f"{name}: docstring lacks {', '.join(missing)}"


def test_section_parser_catches_what_is_missing():
    def bare():
        """Only a summary."""

    def underlined():
        """Summary.

        Parameters
        ----------
        x : float
            Something (rad).

        Returns
        -------
        float

        Raises
        ------
        ValueError
            When x is not finite.
        """

    assert _missing(bare) == ["a 'Parameters' section", "a 'Returns' section", "a 'Raises' section"]
    assert _missing(underlined) == []
