"""The ``jaxrod`` argument parser: the top-level options and one subparser per command, each
added by its command's module (in the order of ``COMMANDS``), and the flags' names for the
messages of bad input."""
from __future__ import annotations

import argparse

from . import analyze, atlas, critical_curve, fit, helix, knot, michell, trefoil

# Each command's module: add_parser(sub, formatter_class) adds its parser, run(args) runs it.
COMMANDS = {module.NAME: module for module in (michell, analyze, trefoil, knot, atlas, helix, critical_curve, fit)}


class Parser(argparse.ArgumentParser):
    """argparse's parser whose usage errors are one line and exit with status 2."""

    def error(self, message):  # one line, status 2
        self.exit(2, f"jaxrod: error: {message} (see {self.prog} --help)\n")


def version():
    """The installed jaxrod's version, or "unknown" in a source tree that is not installed."""
    try:
        from importlib.metadata import version

        return version("jaxrod")
    except Exception:  # noqa: BLE001 -- running from a source tree that is not installed
        return "unknown"


def build_parser():
    """The ``jaxrod`` parser with every command of ``COMMANDS``."""
    p = Parser(prog="jaxrod", description="Equilibria and buckling of twisted elastic rods: Michell's ring, "
               "the twisted trefoil and other knots, the twisted-knot atlas, a knot's critical twists as curves "
               "in D/L, the localized helix of a clamped rod, and the analysis of measured rods. "
               "Give a command and --help for its options.",
               formatter_class=argparse.RawDescriptionHelpFormatter,
               epilog="examples:\n  jaxrod trefoil --N 121 --out results/trefoil\n"
                      "  jaxrod atlas --knots 3_1,4_1 --ratios 0.01,0.02,0.03 --N 101 --out results/atlas\n"
                      "  jaxrod michell --N 128 --out results/michell\n  jaxrod trefoil --help")
    p.add_argument("--version", action="version", version=f"jaxrod {version()}")
    sub = p.add_subparsers(dest="command", parser_class=Parser)
    for module in COMMANDS.values():
        module.add_parser(sub, argparse.RawDescriptionHelpFormatter)
    sub.metavar = "{" + ",".join(sub.choices) + "}"  # every command, in the order of the list below it
    return p


def flag_names(parser, command):
    """{python name: flag} for the options of ``command`` (e.g. phi_min -> --phi-min)."""
    for action in parser._actions:  # the subparsers action holds each command's parser
        if isinstance(action, argparse._SubParsersAction) and command in action.choices:
            return {a.dest: a.option_strings[-1] for a in action.choices[command]._actions
                    if a.option_strings and a.dest not in ("help",)}
    return {}


def in_flags(message, names):
    """The library's message with its parameter names written as the CLI's flags: a name at the
    start of the message ("N must be ..."), and names with an underscore anywhere ("phi_min must
    be < 0 < phi_max"). Other words are left alone (L/D stays L/D, run.json stays run.json)."""
    import re

    for name, flag in names.items():
        if message.startswith(name + " ") or message.startswith(name + ":"):
            message = flag + message[len(name):]
        if "_" in name:  # phi_min, n_samples: never an ordinary word (json, nu, tol may be)
            message = re.sub(rf"(?<![\w-]){re.escape(name)}(?![\w-])", flag, message)
    return message
