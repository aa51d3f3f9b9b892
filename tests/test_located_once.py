"""Each branch end of command 1 is located exactly once on the extended system: the study
brackets it (stable-only continuation), one ``locate_end`` per end runs pseudo-arclength across
the bracket, and the fold or branch-point locator converges on that end once and only once.

Command 1 at N = 61 (its D, L and twist range; the N = 121 run takes ~20 s)."""
import json
import math

import pytest

import jaxrod.continuation.arclength.events as events
import jaxrod.studies.diagram as diagram
from jaxrod.cli import main

# The validation tier (-m validation): command 1 run whole.
pytestmark = pytest.mark.validation


def test_each_end_of_command_1_is_located_exactly_once(tmp_path, monkeypatch):
    ends, located = {}, []

    def counting_locate_end(scene, inst, state, *args, **kwargs):
        end = locate_end(scene, inst, state, *args, **kwargs)
        key = (inst["direction"], tuple(inst["bracket"]))
        assert key not in ends, f"{key} located twice"
        ends[key] = end.event.p
        return end

    def counting(locator):
        def wrapped(*args, **kwargs):
            found = locator(*args, **kwargs)
            located.extend(e.p for e in (found if isinstance(found, list) else [found]) if e.converged)
            return found
        return wrapped

    locate_end = diagram.locate_end
    monkeypatch.setattr(diagram, "locate_end", counting_locate_end)
    monkeypatch.setattr(events, "locate_fold", counting(events.locate_fold))
    monkeypatch.setattr(events, "locate_branch_points", counting(events.locate_branch_points))
    out = tmp_path / "command1"
    assert main(["trefoil", "--D", "8", "--L", "292", "--N", "61", "--phi-min", "-12pi", "--phi-max", "14pi",
                 "--no-extrapolation", "--no-figures", "--quiet", "--out", str(out)]) == 0

    critical = json.loads((out / "critical.json").read_text())
    study_ends = {(c["direction"], tuple(c["bracket"])) for c in critical["instabilities"]}
    assert len(study_ends) >= 3 and {d for d, _ in study_ends} == {"plus", "minus"}
    assert set(ends) == study_ends  # every end the study bracketed was handed on, once
    # the study narrows an end's bracket only to bracket_tol where a fold or branch point is in
    # evidence (the exact location follows): wider than tol, for a fold (a jump) too
    widths = {c["kind"]: abs(c["bracket"][1] - c["bracket"][0]) for c in critical["instabilities"]}
    assert widths.get("jump", 0.0) > 2e-4 * math.pi and max(widths.values()) <= 0.02 * math.pi
    for (direction, bracket), phi in ends.items():
        # located inside its own bracket (to the study's tol), and by one converged location only
        assert min(bracket) - 2e-4 * math.pi <= phi <= max(bracket) + 2e-4 * math.pi, (direction, bracket, phi)
        assert sum(abs(p - phi) <= 1e-9 * abs(phi) for p in located) == 1, (phi, located)
