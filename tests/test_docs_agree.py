"""Defaults and documentation agree with the code (the code is the reference): the contact
stiffness's unit, the atlas's --ratios help, and the README's results table against the committed
output of command 1."""
import json
import math
import pathlib
import re

import jaxrod as jr
from jaxrod import cli
from jaxrod.studies import atlas
from jaxrod.model import contact, scenes

REPO = pathlib.Path(__file__).resolve().parent.parent
# the user documentation: the README and the pages of the docs site
README = "\n".join(p.read_text(encoding="utf-8") for p in [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))])


def _help_of(command, flag):
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    return next(a.help for a in sub._actions if flag in a.option_strings)


def test_the_contact_stiffness_has_one_unit_everywhere():
    # contact_energy multiplies the double integral by kappa_c * B / D**3.
    x = jr.trefoil(D=8.0, L=292.0, N=61)
    assert x.contact_stiffness == scenes.DEFAULT_CONTACT_STIFFNESS
    texts = {"jaxrod.model.contact": contact.__doc__, "closed_curve": scenes.closed_curve.__doc__,
             "trefoil --contact-stiffness": _help_of("trefoil", "--contact-stiffness"),
             "atlas --contact-stiffness": _help_of("atlas", "--contact-stiffness"), "README": README}
    for where, text in texts.items():
        assert "B/D^2" not in text and "B/D²" not in text, where
        assert "B/D^3" in text or "B / D^3" in text or "B/D³" in text, where


def test_the_atlas_help_claims_no_minimum_the_code_does_not_enforce():
    assert "at least" not in _help_of("atlas", "--ratios")
    assert len(atlas.atlas_cases(["3_1"], [0.02, 0.03], [101], atlas.AtlasSettings())) == 4


def test_the_readme_results_table_is_command_1s_output():
    # benchmarks/results/command1_critical.json: critical.json of the README's command 1.
    crit = json.loads((REPO / "benchmarks" / "results" / "command1_critical.json").read_text())
    row = next(line for line in README.splitlines() if line.startswith("| jaxrod N = 121 (command 1)"))
    (tight, t_err), (opening, o_err) = re.findall(r"(−?[\d.]+) π ± ([\d.e-]+) π", row)
    for shown, err, key in ((tight, t_err, "phi_minus"), (opening, o_err, "phi_plus")):
        value = float(shown.replace("−", "-"))
        assert value == round(crit[key] / math.pi, 5), (key, value, crit[key] / math.pi)
        assert float(err) == float(f"{crit[key + '_error'] / math.pi:.0e}"), (key, err)

