"""``jaxrod knot``: the twist study of the trefoil command for another knot, named or read from a
file (the study itself: ``jaxrod.cli.trefoil``)."""
from __future__ import annotations

from . import trefoil
from .common import ANGLES

NAME = "knot"

HELP = f"""\
The twist study of the trefoil command for another knot: the figure-eight knot 4_1, the
cinquefoil 5_1 (torus knot T(2,5)), the three-twist knot 5_2 (or the trefoil 3_1), each from a
published parametrisation and refused below its ideal ropelength L/D; or any closed curve read
from a file (--curve: CSV with an x,y,z header or three columns, or .npy of shape (M, 3); it is
resampled to N nodes and scaled to length L; its linking number at zero twist, Lk0, is the
integer nearest its writhe unless --lk0 gives it: that is the untwisted rod only if the curve is
close to its relaxed shape, and a warning says when the rod relaxed at zero twist still stores
more than a quarter turn). Lengths in mm, E in MPa. {ANGLES}

Writes the same files as the trefoil command, and resumes the same way.

examples:
  jaxrod knot 4_1 --D 8 --L 292 --N 121 --phi-min -12pi --phi-max 12pi --out results/figure_eight
  jaxrod knot --curve my_knot.csv --D 8 --L 400 --N 161 --out results/my_knot
"""


def add_parser(sub, formatter_class):
    """Adds the knot command's parser to the subparsers ``sub``."""
    k = sub.add_parser(NAME, help="the same twist study for 4_1, 5_1, 5_2 or any closed curve from a file",
                       description=HELP, formatter_class=formatter_class)
    k.add_argument("name", nargs="?", choices=("3_1", "4_1", "5_1", "5_2"), help="the knot (or give --curve)")
    k.add_argument("--curve", default=None, help="closed curve to tie the rod along (.csv or .npy), instead of a name")
    k.add_argument("--lk0", type=int, default=None,
                   help="linking number of the untwisted rod (default: the integer nearest the curve's writhe)")
    trefoil.add_study_arguments(k, "results/knot", "above the knot's ideal ropelength times D")


def run(args):
    """Runs ``jaxrod knot`` with the parsed ``args`` (the trefoil command's study); returns the exit status."""
    return trefoil.run(args)
