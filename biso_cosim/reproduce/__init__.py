"""Reproductions of the source papers' claims: each module has ``run(out_dir, ...) -> dict``
that writes ``report.md``, figures and ``results.json`` into ``out_dir``.

``biso-cosim reproduce NAME --out DIR`` runs one of them.
"""

from __future__ import annotations

import importlib
from pathlib import Path

PAPERS = {
    "aleshkin2024": "Aleshkin et al. (2024): BISO, cross-linked positional correction (seed 000)",
    "ibrahim2020": "Ibrahim & Lukyanov (2020): GNSS-aided attitude with and without a Kalman filter (seed 002)",
    "litmanovich2002": "Litmanovich (2002): coning, sculling and position from multiple integrals (seed 004)",
}
"""Reproducible papers: name → what it covers."""


def run(name: str, out_dir: str | Path, **options) -> dict:
    """Run the reproduction of paper ``name`` into ``out_dir``."""
    if name not in PAPERS:
        raise ValueError(f"unknown paper {name!r}; known: {', '.join(PAPERS)}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return importlib.import_module(f"biso_cosim.reproduce.{name}").run(out, **options)
