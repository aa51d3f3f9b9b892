"""The command line's help texts agree with its parser and with the code behind it, and every
command's --json names the critical twists with jaxrod.io.schema's keys.

The JSON tests run each command's own JSON path on real results without computing them again:
command 1's critical.json and the committed atlas (benchmarks/results), and, for --accuracy, a
known sequence of levels in place of the continuation."""
import json
import math
import pathlib
import re
import types

import pytest

from jaxrod import cli
from jaxrod.studies.runs import critical_json

REPO = pathlib.Path(__file__).resolve().parent.parent
PI = math.pi
KINDS = {"fold", "branch_point", "snap", "jump", "unstable"}


def _subparsers(parser):
    return next(a for a in parser._actions if a.dest == "command")


def _commands(parser=None):
    return _subparsers(parser or cli.build_parser()).choices


def _options(parser=None):
    """(command, action) for every argument of every command (-h left out)."""
    for name, sub in _commands(parser).items():
        for action in sub._actions:
            if action.dest != "help":
                yield name, action


def _flag(action):
    return action.option_strings[-1] if action.option_strings else action.dest


# ------------------------------------------------------------------------------------ help texts
def test_usage_help_and_dispatch_name_every_command(capsys):
    parser = cli.build_parser()
    commands = list(_commands(parser))
    assert {"michell", "analyze", "trefoil", "knot", "atlas", "helix", "critical-curve"} <= set(commands)
    assert re.search(r"\{([^}]*)\}", parser.format_usage()).group(1).split(",") == commands
    assert cli.main(["--help"]) == 0
    usage = capsys.readouterr().out.split("\n\n")[0]
    assert list(cli.COMMANDS) == commands  # each command parsed is run by its module
    for command in commands:
        assert command in usage.split("{")[1], command
        assert f"``jaxrod {command}" in cli.__doc__, command
        assert callable(cli.COMMANDS[command].run), command


_DEFAULT = re.compile(r"\bdefault\b(?P<colon>:?)\s*")
_NUMBER = re.compile(r"(?<![\w.])\d+(?:\.\d+)?(?:e-?\d+)?(?![\w.])")


def _stated_defaults(text):
    """[(colon, value)] for each "default X" / "default: words" in a help text: X up to ')', ';',
    ', ' or ': '; the words up to ')' or ';'."""
    found = []
    for m in _DEFAULT.finditer(text):
        rest = text[m.end():]
        if m.group("colon"):
            value = re.split(r"[);]", rest)[0]
        else:
            value = re.split(r"\)|;|, |: ", rest)[0]
        found.append((bool(m.group("colon")), value.strip()))
    return found


def _resolved_in_code():
    """Defaults that a help text states for an option whose parser default is None (the command
    resolves it): (command, dest) -> the values, from the code's own constants."""
    from jaxrod.model.scenes import DEFAULT_CONTACT_STIFFNESS

    return {("trefoil", "N"): [cli.STUDY_NODES, cli.ACCURACY_NODES], ("knot", "N"): [cli.STUDY_NODES, cli.ACCURACY_NODES],
            ("trefoil", "contact_stiffness"): [DEFAULT_CONTACT_STIFFNESS],
            ("knot", "contact_stiffness"): [DEFAULT_CONTACT_STIFFNESS]}


def _same(action, text):
    default = action.default
    if action.type is cli.parse_angle:
        return math.isclose(cli.parse_angle(text), default, rel_tol=1e-12)
    if isinstance(default, bool):
        return False
    if isinstance(default, (int, float)):
        try:
            return float(text) == default
        except ValueError:
            return False
    return text == str(default)


def test_every_stated_default_and_choice_is_the_codes():
    from jaxrod.studies import atlas, critical_curve
    from jaxrod.model import scenes

    resolved = _resolved_in_code()
    problems = []
    for command, action in _options():
        where = f"{command} {_flag(action)}"
        stated = _stated_defaults(action.help or "")
        if action.default not in (None, False) and not stated and action.nargs != 0:
            problems.append(f"{where}: default {action.default!r} not stated")
        for colon, value in stated:
            if colon:  # words: the command resolves it; any number in them is the code's
                if action.default not in (None, False):
                    problems.append(f"{where}: 'default: {value}' but the parser's default is {action.default!r}")
                for number in _NUMBER.findall(value):
                    if float(number) not in resolved.get((command, action.dest), []):
                        problems.append(f"{where}: 'default: {value}': {number} is not the code's")
            elif not value:
                problems.append(f"{where}: '(default)' states no value")
            elif action.default is None:
                if not _NUMBER.fullmatch(value) or float(value) not in resolved.get((command, action.dest), []):
                    problems.append(f"{where}: default {value!r}, the code's {resolved.get((command, action.dest))}")
            elif not _same(action, value):
                problems.append(f"{where}: help says default {value}, the parser's is {action.default!r}")
    assert not problems, "\n".join(problems)

    # choices: exactly what the code accepts; every knot named in a help text is one of them
    knots = set(scenes.IDEAL_ROPELENGTH)
    with_choices = {(command, action.dest): set(action.choices) for command, action in _options() if action.choices}
    assert with_choices == {("knot", "name"): knots, ("critical-curve", "knot"): knots,
                            ("trefoil", "chirality"): {"right", "left"},
                            ("helix", "root"): {"stable", "small", "large", "both"}}
    for chirality in ("right", "left"):
        scenes.trefoil_points(8, chirality)
    with pytest.raises(ValueError, match="chirality"):
        scenes.trefoil_points(8, "up")
    commands = _commands()
    assert commands["atlas"].get_default("knots") == ",".join(atlas.KNOTS) and set(atlas.KNOTS) == knots
    for command, sides in (("atlas", atlas.SIDES), ("critical-curve", tuple(critical_curve.SIDE_SIGNS))):
        assert commands[command].get_default("sides") == ",".join(sides) == "plus,minus"
    texts = [a.help or "" for _, a in _options()] + [s.description or "" for s in commands.values()] + \
        [a.help or "" for a in _subparsers(cli.build_parser())._choices_actions]
    for text in texts:
        assert set(re.findall(r"\b\d_\d\b", text)) <= knots, text


def _minimums():
    """(command, flag) -> the smallest value the command takes, from the code."""
    from jaxrod.model.scenes import MIN_TREFOIL_NODES
    from jaxrod.studies.runs.michell import MICHELL_MIN_NODES

    return {("michell", "--N"): MICHELL_MIN_NODES, ("trefoil", "--N"): MIN_TREFOIL_NODES,
            ("knot", "--N"): MIN_TREFOIL_NODES, ("atlas", "--N"): MIN_TREFOIL_NODES,
            ("critical-curve", "--N"): MIN_TREFOIL_NODES, ("analyze", "--n-samples"): 4,
            ("analyze", "--smoothing-modes"): 1}


def test_every_stated_minimum_is_enforced_with_an_error_naming_the_flag(tmp_path, capsys):
    minimums = _minimums()
    claims = {(command, _flag(action)): [int(k) for k in re.findall(r"at least (\d+)(?![\d.]| per| D)", action.help)]
              for command, action in _options() if action.help and "at least" in action.help}
    claims = {key: ks for key, ks in claims.items() if ks}
    assert set(claims) == set(minimums), claims  # each bound the code enforces is stated, and no other
    argv = {"michell": [], "trefoil": [], "knot": ["4_1"], "atlas": ["--knots", "3_1", "--ratios", "0.03"],
            "critical-curve": ["--ratios", "0.03"], "analyze": ["centre.csv", "line.csv"]}
    for (command, flag), k in minimums.items():
        assert claims[(command, flag)] == [k], (command, flag)
        out = [] if command in ("michell", "analyze") else ["--out", str(tmp_path / command)]
        assert cli.main([command, *argv[command], flag, str(k - 1), *out, "--quiet"]) == 2, (command, flag)
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and flag in err[0] and f"at least {k}" in err[0], (command, flag, err)


def test_every_angle_option_takes_negative_values_and_multiples_of_pi():
    parser = cli.build_parser()
    before = {"analyze": ["centre.npz"], "fit": ["onsets.csv"]}
    angles = [(command, action) for command, action in _options(parser) if action.type is cli.parse_angle]
    assert {_flag(a) for _, a in angles} == set(cli.ANGLE_OPTIONS)
    for command, action in angles:
        for text, value in (("-8.5pi", -8.5 * PI), ("0.25*pi", 0.25 * PI), ("-3.7", -3.7), ("12pi", 12 * PI)):
            args = parser.parse_args(cli.join_angle_values([command, *before.get(command, []), _flag(action), text]))
            assert getattr(args, action.dest) == pytest.approx(value, rel=1e-15), (command, _flag(action), text)


# ------------------------------------------------------------------------------------- --json keys
def _strict(text):
    """The JSON printed, refusing NaN and Infinity (not JSON)."""
    def refuse(name):
        raise AssertionError(f"{name} in the JSON")
    return json.loads(text, parse_constant=refuse)


def _check_side(record):
    from jaxrod.io import schema

    assert set(schema.SIDE_KEYS) <= set(record), record
    assert record["side"] in schema.SIDES
    if record["phi_star"] is None:
        assert record["phi_star_over_pi"] is None and record["phi_error"] is None and record["kind"] is None
        return
    assert record["phi_star_over_pi"] == pytest.approx(record["phi_star"] / PI, rel=1e-15)
    assert (record["phi_star"] > 0) == (record["side"] == "plus"), record
    assert record["phi_error"] is None or record["phi_error"] >= 0
    assert record["kind"] in KINDS, record


def _check_both_sides(obj):
    """The both-sides keys, each side's four quantities as a one-side record would have them."""
    from jaxrod.io import schema

    for side in schema.SIDES:
        _check_side({"side": side, **{key: obj[schema.side_key(side, key)] for key in schema.SUFFIXES}})
    assert [k for k in obj if k in schema.KEYS][:8] == [schema.side_key(s, k) for s in schema.SIDES
                                                        for k in schema.SUFFIXES]  # first, in one order


def _command1():
    return json.loads((REPO / "benchmarks" / "results" / "command1_critical.json").read_text())


def test_trefoil_and_knot_study_json(monkeypatch, tmp_path, capsys):
    # The study's JSON path with command 1's results (critical.json) in place of the continuation.
    import jaxrod.studies.twist as study

    critical = _command1()

    def known_study(scene, phi_min, phi_max, options, **kwargs):
        return types.SimpleNamespace(critical=critical, table={"phi": [0.0] * 7}, seconds=1.5, seconds_total=2.5,
                                     end_states=[])

    monkeypatch.setattr(study, "twist_study", known_study)
    common = ["--N", "61", "--no-extrapolation", "--no-figures", "--json", "--quiet"]
    for i, argv in enumerate((["trefoil", "--stable-only"], ["trefoil", "--serial"], ["knot", "3_1"])):
        out = tmp_path / str(i)
        assert cli.main([*argv, *common, "--out", str(out)]) == 0, capsys.readouterr().err
        printed = _strict(capsys.readouterr().out)
        _check_both_sides(printed)
        assert printed["phi_plus"] == critical["phi_plus"] and printed["phi_minus"] == critical["phi_minus"]
        assert printed["phi_plus_error"] == critical["phi_plus_error"]
        assert printed["phi_plus_kind"] == printed["phi_minus_kind"] == "jump"  # command 1's first ends
        assert printed == json.loads((out / "summary.json").read_text())
        for key in ("tightening_side", "seconds", "steps", "N", "D", "L", "nu", "contact_stiffness", "out"):
            assert key in printed, key
    # the text output: an end that was not located carries its bracket, and says why
    assert cli.main(["trefoil", "--stable-only", "--N", "61", "--no-extrapolation", "--no-figures", "--quiet",
                     "--out", str(tmp_path / "text")]) == 0
    text = capsys.readouterr().out
    assert f"+- {critical['phi_plus_error'] / math.pi:.1e} pi: the study's bracket" in text and "(--stable-only)" in text
    # an end located on the extended system: its kind, and no bracket
    summary = {"phi_plus": 20.3, "phi_plus_error": None, "phi_plus_located": {"kind": "fold"}, "phi_minus": None,
               "phi_minus_error": None, "steps": 3}
    out = critical_json(summary, critical=critical)
    _check_both_sides(out)
    assert out["phi_plus_kind"] == "fold" and out["phi_plus_error"] is None and out["phi_minus_kind"] is None
    assert out["steps"] == 3 and out["phi_plus_located"] == {"kind": "fold"}


def test_trefoil_accuracy_json_has_the_studys_keys(monkeypatch, tmp_path, capsys):
    # --accuracy with a known convergence phi*(N) = phi_inf + c / N^2 + d / N^3 in place of the levels
    import numpy as np

    import jaxrod.studies.accuracy as conv
    import jaxrod.solve.equilibrium as equilibrium

    limits = {"plus": 6.42 * PI, "minus": -11.09 * PI}

    def known_level(scene, side, phi_start, start, span, step, tol, say, cancel):
        N = int(scene.n_nodes)
        phi = limits[side] + math.copysign(1.0, limits[side]) * (4e3 / N ** 2 - 2e4 / N ** 3)
        q = np.asarray(scene.q_init)
        states = ((phi_start, q), (0.5 * (phi_start + phi), q))
        return conv.Level(N, phi, tol, "jump", phi_start, 0.01, states), "", states

    monkeypatch.setattr(conv, "level_of_side", known_level)
    monkeypatch.setattr(equilibrium, "relax_to_minimum", lambda scene, phi, q0=None: None)
    assert cli.main(["trefoil", "--accuracy", "0.01pi", "--N-max", "481", "--no-figures", "--serial", "--json",
                     "--quiet", "--out", str(tmp_path / "acc")]) == 0
    printed = _strict(capsys.readouterr().out)
    _check_both_sides(printed)
    for side in ("plus", "minus"):
        detail = printed[side]  # the side's convergence, as before, with the one-side keys
        _check_side(detail)
        assert printed[f"phi_{side}"] == detail["phi_star"] == pytest.approx(limits[side], abs=0.01 * PI)
        assert printed[f"phi_{side}_error"] == detail["phi_error"] == detail["error"] <= 0.01 * PI
        assert printed[f"phi_{side}_kind"] == detail["kind"] == "jump"
        assert [lv["N"] for lv in detail["levels"]] == [61, 121, 241]
    for key in ("D", "L", "nu", "contact_stiffness", "accuracy", "seconds", "out"):
        assert key in printed, key


def test_michell_json(monkeypatch, capsys):
    import numpy as np

    import jaxrod.continuation as continuation

    def known(scene, phi0, phi1, options, observer=None):
        return types.SimpleNamespace(phi=5.2060575 * PI, phi_error=3e-9, multiplicity=2, dlambda_dphi=-0.4,
                                     hessian_evaluations=5, scan=[(0.0, 0, np.zeros(2))])

    monkeypatch.setattr(continuation, "critical_twist", known)
    assert cli.main(["michell", "--N", "8", "--json", "--quiet"]) == 0
    printed = _strict(capsys.readouterr().out)
    _check_side(printed)
    assert printed["side"] == "plus" and printed["phi_star"] == 5.2060575 * PI and printed["kind"] == "unstable"
    assert printed["phi_error"] == printed["phi_error_bound"] == 3e-9
    for key in ("phi_star_analytic", "rel_error", "N", "nu", "seconds", "multiplicity"):
        assert key in printed, key


def test_atlas_and_critical_curve_rows_are_one_side_records(monkeypatch, tmp_path, capsys):
    from jaxrod.studies import atlas, critical_curve
    from jaxrod.io import schema

    rows = atlas.read_atlas(str(REPO / "benchmarks" / "results" / "atlas"))  # some cases without an end
    monkeypatch.setattr(atlas, "run_atlas", lambda *a, **k: rows)
    monkeypatch.setattr(atlas, "report", lambda out: f"{out}/atlas.md")
    assert cli.main(["atlas", "--knots", "3_1", "--ratios", "0.03", "--N", "40", "--no-figures", "--json", "--quiet",
                     "--out", str(tmp_path / "atlas")]) == 0
    printed = _strict(capsys.readouterr().out)["rows"]
    endless = sum(not math.isfinite(r["phi_star"]) for r in rows)
    assert endless > 0 and len(printed) == len(rows) and sum(r["phi_star"] is None for r in printed) == endless
    for row, original in zip(printed, rows):
        _check_side(row)
        assert set(atlas.FIELDS) <= set(row) and row["knot"] == original["knot"]
    # critical-curve's rows (its CSV columns): the same names; located points carry no phi_error
    assert set(schema.SIDE_KEYS) - {"phi_error"} <= set(critical_curve.CSV_COLUMNS)


def test_the_schema_is_one_table_in_the_readme():
    from jaxrod.io import schema

    readme = (REPO / "docs" / "guides" / "twist-study.md").read_text(encoding="utf-8")  # the docs' --json section
    assert schema.markdown_table() in readme
    assert set(schema.KEYS) == set(schema.SIDE_KEYS) | {schema.side_key(s, k) for s in schema.SIDES
                                                        for k in schema.SUFFIXES}
    for key, (unit, meaning) in schema.KEYS.items():
        assert unit and meaning, key
    for command in ("michell", "trefoil", "knot", "atlas"):
        help_text = next(a.help for a in _commands()[command]._actions if a.dest == "json")
        assert "jaxrod.io.schema" in help_text, command
