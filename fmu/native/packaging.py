"""What every FMU we build carries beside its binary, and the zip: ``documentation/`` (an
index page listing the variables, and the FMI licence) and the archive itself. Shared by the
native FMUs (`build`) and the Python-based ones (`python_shell`)."""

from __future__ import annotations

import html
import shutil
import zipfile
from pathlib import Path

from biso_cosim import __version__
from biso_cosim.fmu.native import INCLUDE_DIR
from biso_cosim.fmu.native.model_description import SUMMARY

__all__ = ["write_documentation", "zip_fmu"]


def _index_html(name: str, fmi_version: int, about_html: str) -> str:
    from biso_cosim.fmu.variables import variables_of

    rows = "\n".join(
        f"<tr><td><code>{html.escape(v.name)}</code></td><td>{v.type}</td><td>{v.causality}</td>"
        f"<td>{v.variability}</td><td>{html.escape(v.unit)}</td><td>{html.escape(str(v.start))}</td>"
        f"<td>{html.escape(v.description)}</td></tr>" for v in variables_of(name))
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{name}</title></head><body>"
            f"<h1>{name} (FMI {fmi_version}.0 co-simulation)</h1><p>{html.escape(SUMMARY[name])}</p>"
            f"<p>biso_cosim {__version__}. {about_html} Guide: docs/fmu.md of the biso_cosim package.</p>"
            "<table border='1'><tr><th>variable</th><th>type</th><th>causality</th><th>variability</th>"
            f"<th>unit</th><th>start</th><th>description</th></tr>\n{rows}</table></body></html>\n")


def write_documentation(fmu_root: Path, name: str, fmi_version: int, about_html: str) -> None:
    """``documentation/index.html`` (the FMU's summary, ``about_html`` on how it runs, its
    variables) and ``documentation/LICENSE-FMI.txt`` under ``fmu_root``."""
    folder = fmu_root / "documentation"
    folder.mkdir()
    (folder / "index.html").write_text(_index_html(name, fmi_version, about_html), "utf-8")
    shutil.copyfile(INCLUDE_DIR / "LICENSE-FMI.txt", folder / "LICENSE-FMI.txt")


def zip_fmu(fmu_root: Path, path: Path) -> Path:
    """Zip the tree under ``fmu_root`` into the .fmu ``path`` (sorted entries, so that two
    builds of the same tree list the same files in the same order)."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for item in sorted(fmu_root.rglob("*")):
            if item.is_file():
                z.write(item, item.relative_to(fmu_root).as_posix())
    return path
