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
    # the comments' numbers: both ends at +-5.23593 pi (N = 64), the sensitivity phi* / (1 + nu)
    assert abs(ends.plus.phi / math.pi - 5.23593) < 1e-5 and abs(ends.minus.phi + ends.plus.phi) < 1e-8
    assert "branch_point: phi* = +5.23593 pi" in out and "continuum: 5.19615 pi" in out
    assert abs(namespace["slope"] - ends.plus.phi / 1.5) < 1e-6 * ends.plus.phi and "0.6667" in out


def test_the_readme_links_exist():
    root = os.path.dirname(README)
    for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", _text()):
        assert os.path.exists(os.path.join(root, target)), target
