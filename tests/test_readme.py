"""Every ```python block of README.md runs (issue 8, acceptance 4): in order, in one namespace,
in a temporary folder (the tour writes two CSV files)."""
import os
import re

README = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "README.md")


def _python_blocks():
    text = open(README, encoding="utf-8").read()
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def test_readme_has_python_blocks():
    assert len(_python_blocks()) >= 2


def test_readme_python_blocks_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "readme"}
    for number, block in enumerate(_python_blocks()):
        exec(compile(block, f"README.md python block {number}", "exec"), namespace)
    # The numbers the comments promise.
    import math

    assert abs(namespace["cp"].phi / math.pi - 5.2061) < 1e-4 and namespace["cp"].multiplicity == 2
    end = namespace["end"]
    assert abs(end.phi / math.pi - 6.60) < 0.01 and namespace["path"].points[-1].branch == "buckled+"
    res, state = namespace["res"], namespace["state"]
    assert abs(state.Lk - 6.0) < 1e-8 and abs(res.Lk_frames - 6.0) < 0.05
