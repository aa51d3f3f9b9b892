"""``analyze`` says when its input is doubtful (issue 8, defect 4) instead of returning silent
nonsense: a stripe that covers part of the rod, an open curve treated as closed, nodes paired
with another strand's line. Clean data gives no warning."""
import math

import numpy as np
import pytest

from helpers import analyze_checked

TWO_PI = 2 * math.pi


def _ribbon(turns=3, m=120, offset=0.1):
    """A unit circle and a line wound `turns` times around it (Lk = turns)."""
    t = TWO_PI * np.arange(m) / m
    x = np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)
    inward, up = -x, np.array([0.0, 0.0, 1.0])
    stripe = x + offset * (np.cos(turns * t)[:, None] * inward + np.sin(turns * t)[:, None] * up)
    return x, stripe


_analyze = analyze_checked  # the warnings it issues are the ones it returns


def test_clean_ribbon_gives_no_warning():
    res = _analyze(*_ribbon())
    assert res.warnings == ()
    assert res.Lk_frames == pytest.approx(3.0, abs=1e-6) and res.Lk_exact == pytest.approx(3.0, abs=1e-9)


def test_a_stripe_covering_part_of_the_rod_is_flagged():
    x, stripe = _ribbon()
    res = _analyze(x, stripe[:40])  # the stripe drawn along a third of the rod only
    text = " ".join(res.warnings)
    assert "times as long as the centreline" in text
    assert "ends are" in text  # the stripe's two ends are far apart, yet it was closed


def test_an_open_curve_treated_as_closed_is_flagged():
    t = np.linspace(0.0, 4 * math.pi, 100)
    helix = np.stack([np.cos(t), np.sin(t), 0.3 * t], axis=1)
    stripe = helix + 0.05 * np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)
    res = _analyze(helix, stripe)  # closed=True by default
    assert any(w.startswith("centreline: its ends are") and "closed=False" in w for w in res.warnings)
    assert not any("ends are" in w for w in _analyze(helix, stripe, closed=False).warnings)


def test_nodes_paired_with_another_strand_are_flagged():
    # A flat loop pinched into a neck where two strands pass 0.1 apart, its line wound twice
    # around it at 0.06 from the centreline: near the neck a node's normal plane meets the
    # line of the other strand nearer than its own, and the pairing jumps between strands.
    t = TWO_PI * np.arange(400) / 400
    x = np.stack([2 * np.cos(t), np.sin(t) * (0.05 + 0.95 * np.abs(np.cos(t)) ** 0.25), 0 * t], axis=1)
    tangent = np.roll(x, -1, axis=0) - np.roll(x, 1, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    inward = np.stack([-tangent[:, 1], tangent[:, 0], 0 * t], axis=1)
    stripe = x + 0.06 * (np.cos(2 * t)[:, None] * inward + np.sin(2 * t)[:, None] * np.array([0.0, 0.0, 1.0]))
    res = _analyze(x, stripe)
    assert any("another strand" in w for w in res.warnings), res.warnings
    assert np.ptp(res.tau) > 10.0  # what the warning is about: the profile is nonsense there
