"""Every ```python block of README.md runs, in order, in one namespace, in a temporary folder, and
the numbers its comments promise are what it computes; the README stays a short front page."""
import math
import os
import re

README = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "README.md")


def _text():
    return open(README, encoding="utf-8").read()


def _python_blocks():
    return re.findall(r"^```python\n(.*?)^```", _text(), flags=re.S | re.M)


def test_readme_is_short_with_one_first_example():
    assert len(_text().splitlines()) <= 200
    blocks = _python_blocks()
    assert len(blocks) == 1 and len(blocks[0].strip().splitlines()) <= 20


def test_readme_python_blocks_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "readme"}
    for number, block in enumerate(_python_blocks()):
        exec(compile(block, f"README.md python block {number}", "exec"), namespace)
    out = capsys.readouterr().out
    ends = namespace["ends"]
    # the comments' numbers: both ends at +-5.23593 pi (N = 64), mirror images of each other within
    # their location errors; the sensitivity phi* / (1 + nu)
    assert abs(ends.plus.phi / math.pi - 5.23593) < 1e-5
    assert abs(ends.minus.phi + ends.plus.phi) <= ends.plus.phi_error + ends.minus.phi_error
    assert "branch_point: phi* = +5.23593 pi" in out and "continuum: 5.19615 pi" in out
    assert abs(namespace["slope"] - ends.plus.phi / 1.5) < 1e-6 * ends.plus.phi and "0.6667" in out


def test_the_readme_links_exist():
    root = os.path.dirname(README)
    for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", _text()):
        assert os.path.exists(os.path.join(root, target)), target


def test_readme_figures_are_the_stored_results():
    # the numbers the README quotes for command 1 and the accuracy mode are those in benchmarks/results
    import json
    import pathlib

    results = pathlib.Path(README).parent / "benchmarks" / "results"
    text = open(README, encoding="utf-8").read()
    ends = json.loads((results / "redesign_same_answers.json").read_text())["cases"]["command1"]["ends_new"]
    assert f"{ends[0]:+.7f} π (opening)" in text and f"{ends[-1]:+.7f} π (tightening)".replace("-", "−") in text
    acc = json.loads((results / "accuracy_trefoil.json").read_text())
    plus, minus = acc["plus"], acc["minus"]
    assert f"{plus['phi_star_over_pi']:+.3f} π ± {plus['error_over_pi']:.0e} π".replace("e-04", "e-4") in text
    assert f"{minus['phi_star_over_pi']:.3f} π ± {minus['error_over_pi']:.1e} π".replace("-", "−", 1).replace(
        "e-03", "e-3") in text
