"""How jaxrod's figures end: laid out, then saved and closed when given a path."""
from __future__ import annotations

import matplotlib.pyplot as plt


def finish(fig, path):
    """``fig`` laid out (``tight_layout``); with ``path`` saved at 120 dpi and closed."""
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig
