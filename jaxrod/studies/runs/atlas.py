"""The twisted-knot atlas as ``jaxrod atlas`` runs it: every (knot, D/L, N, side) case's critical
twist (``jaxrod.studies.atlas.run_atlas``), then its report (atlas.md) and figure (atlas.png), and
the rows as one JSON object.

    from jaxrod.studies.runs import AtlasOptions, run_atlas_study, write_atlas_summary
    options = AtlasOptions(knots=("3_1",), ratios=(0.02, 0.03), N=(101,), out="results/atlas")
    rows = run_atlas_study(options)          # a dict per case, atlas.csv's columns (phi_star in rad)
    write_atlas_summary(options)
"""
from __future__ import annotations

import dataclasses

from .. import atlas


@dataclasses.dataclass(frozen=True)
class AtlasOptions:
    """knots, ratios (D/L), N (node counts) and sides ("plus", "minus") span the cases; settings,
    the ``AtlasSettings`` every case shares; out, the folder (resumed unless fresh); figures:
    draw atlas.png."""

    knots: tuple = atlas.KNOTS
    ratios: tuple = (0.01, 0.015, 0.02, 0.0274, 0.03, 0.035)
    N: tuple = (101,)
    sides: tuple = atlas.SIDES
    settings: atlas.AtlasSettings = dataclasses.field(default_factory=atlas.AtlasSettings)
    out: str = "results/atlas"
    fresh: bool = False
    figures: bool = True


def atlas_cases_of(options):
    """The ``AtlasCase`` list of ``options``, each case checked now (``atlas.atlas_cases``)."""
    return atlas.atlas_cases(list(options.knots), list(options.ratios), list(options.N), options.settings,
                             list(options.sides))


def run_atlas_study(options, client=None, on_row=None):
    """Every case's row (a dict, atlas.csv's columns), written to options.out/atlas.csv as each
    finishes. client: a Dask client that runs the cases (None: in this process); on_row(row,
    done, total) after each case."""
    return atlas.run_atlas(list(options.knots), list(options.ratios), list(options.N), settings=options.settings,
                           out=options.out, client=client, fresh=options.fresh, on_row=on_row,
                           sides=list(options.sides))


def write_atlas_summary(options):
    """Writes atlas.md and (with figures) atlas.png from the rows on file; returns their paths."""
    written = [atlas.report(options.out)]
    if options.figures:
        written.append(atlas.figures(options.out))
    return written


def atlas_json(rows):
    """atlas's JSON: {"rows": [...]}, a row per case with atlas.csv's columns, its critical twist
    under jaxrod.io.schema's one-side keys (side, phi_star, phi_star_over_pi, phi_error, kind: null,
    not NaN or 'none', where the side has no end within the span)."""
    from ...io import schema

    return schema.json_safe({"rows": [{**r, **schema.side_record(r["side"], r["phi_star"], r["phi_error"], r["kind"])}
                                      for r in rows]})
