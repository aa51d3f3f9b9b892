"""Command line: ``jaxrod michell ...``, ``jaxrod trefoil ...``, ``jaxrod knot ...``, ``jaxrod atlas ...``,
``jaxrod analyze CENTRELINE ECCENTRIC ...``, ``jaxrod helix ...``, ``jaxrod critical-curve ...``,
``jaxrod fit MEASUREMENTS ...``.

One module per command (``michell``, ``analyze``, ``trefoil``, ``knot``, ``atlas``, ``helix``,
``critical_curve``, ``fit``): each adds its parser, checks its arguments, builds the options of a study in
``jaxrod.studies`` (the pipelines: ``jaxrod.studies.runs``), calls it and prints the result. The
parser is assembled in ``parser``, the shared pieces (angles, --out, progress, compile cache) are
in ``common``, and ``main`` runs a command.

Progress goes to stderr; results to stdout (``--json``: one JSON object); figures and data
(PNG, CSV, JSON) into ``--out DIR``. Bad input exits with status 2, a computation that fails
(no critical twist in range, no equilibrium) with status 1, Ctrl-C with 130: each with one line
on stderr that says what to change (or, for an interrupted study, that it resumes).
"""
from .common import ANGLE_OPTIONS, Progress, enable_compilation_cache, join_angle_values, parse_angle
from .main import add_cli_xla_flags, console_main, main
from .parser import COMMANDS, build_parser
from .trefoil import ACCURACY_NODES, PAPER_YOUNG_MODULUS, STUDY_NODES

__all__ = ["main", "console_main", "build_parser", "COMMANDS", "add_cli_xla_flags", "enable_compilation_cache",
           "Progress", "parse_angle", "join_angle_values", "ANGLE_OPTIONS", "PAPER_YOUNG_MODULUS", "STUDY_NODES",
           "ACCURACY_NODES"]
