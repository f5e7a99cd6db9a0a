"""``biso_cosim.envs`` and ``biso_cosim.fmu`` when the package is imported from a source tree.

The repository keeps the Gymnasium environments and the FMU export at its top level,
``envs/`` and ``fmu/`` beside ``biso_cosim/`` (docs/design.md §2), and the build installs
them inside the package (pyproject.toml's ``package-dir``), so that an installed copy has
``biso_cosim/envs`` and ``biso_cosim/fmu`` like any sub-package. Python started in the
repository root puts the source tree first on ``sys.path``: ``import biso_cosim`` then
imports ``./biso_cosim``, which has no ``envs`` or ``fmu`` inside, whatever was installed
(``pip install .`` or ``-e .``). ``install`` adds a finder for exactly these two names that
resolves them to the directories beside the package, as the build maps them; it does
nothing in an installed copy.
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys
from pathlib import Path

__all__ = ["install", "MAPPED"]

MAPPED = {"biso_cosim.envs": "envs", "biso_cosim.fmu": "fmu"}
"""Sub-packages that live beside the package in the repository (pyproject.toml's package-dir)."""


class _SiblingFinder(importlib.abc.MetaPathFinder):
    """Finds the MAPPED sub-packages in the repository root; nothing else."""

    def __init__(self, root: Path):
        self.root = root

    def find_spec(self, fullname, path=None, target=None):
        folder = MAPPED.get(fullname)
        if folder is None:
            return None
        init = self.root / folder / "__init__.py"
        if not init.is_file():
            return None
        return importlib.util.spec_from_file_location(fullname, init,
                                                      submodule_search_locations=[str(init.parent)])


def install(package_dir: str | Path) -> bool:
    """Add the finder if ``package_dir`` (biso_cosim/) is a source tree's: envs/ and fmu/ not
    inside it but beside it, with the repository's pyproject.toml. Returns whether it did."""
    package = Path(package_dir)
    root = package.parent
    if (package / "envs" / "__init__.py").is_file() or not (root / "pyproject.toml").is_file():
        return False
    if not all((root / folder / "__init__.py").is_file() for folder in MAPPED.values()):
        return False
    if not any(isinstance(f, _SiblingFinder) for f in sys.meta_path):
        # before the path finder, for which a stray biso_cosim/envs/__pycache__ is a namespace package
        sys.meta_path.insert(0, _SiblingFinder(root))
    return True
