"""Files written atomically: under a temporary name in the same folder, then renamed, so that a
run killed at any moment leaves either the old file or the new one, never half of one (the
studies and the atlas resume from what is on file)."""
from __future__ import annotations

import csv
import json
import os

import numpy as np

__all__ = ["savez", "write_json", "write_rows"]


def savez(path, **arrays):
    """np.savez to ``path``; the temporary name is hidden (``.tmp-<name>``), outside the
    ``<direction>_*.npz`` pattern that a study's resume counts."""
    folder, name = os.path.split(path)
    tmp = os.path.join(folder, ".tmp-" + name)
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def write_json(path, obj):
    """JSON with sorted keys (the same file whichever order the keys were set in)."""
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(obj, f, indent=2, sort_keys=True)
    os.replace(tmp, path)


def write_rows(csv_path, header, rows):
    """A whole CSV: the header, then ``rows`` (dicts; keys outside the header ignored)."""
    tmp = csv_path + ".tmp"
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=header, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, csv_path)
