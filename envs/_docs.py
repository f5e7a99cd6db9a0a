"""Argument tables of the environments, from one source: the signature (types, defaults) and
the ``ARGUMENTS`` / ``COMMON_ARGUMENTS`` descriptions. They fill the ``{arguments}`` place of
each environment's docstring and the reference part of ``docs/envs.md``."""

from __future__ import annotations

import importlib
import inspect
import re

__all__ = ["arguments_table", "finish_docstring", "reference_markdown"]

_INDENT = "    "


def _descriptions(cls) -> dict[str, str]:
    from biso_cosim.envs._common import COMMON_ARGUMENTS

    return {**COMMON_ARGUMENTS, **cls.ARGUMENTS}


def arguments_table(cls) -> str:
    """The Markdown table of ``cls``'s keyword arguments: name, type, default, description."""
    descriptions = _descriptions(cls)
    rows = ["| Parameter | Type | Default | Description |", "|---|---|---|---|"]
    for name, p in inspect.signature(cls.__init__).parameters.items():
        if name == "self":
            continue
        if name not in descriptions:
            raise RuntimeError(f"{cls.__name__}: argument {name!r} has no description")
        kind = str(p.annotation).replace("|", "\\|")
        rows.append(f"| `{name}` | `{kind}` | `{p.default!r}` | {descriptions[name]} |")
    return "\n".join(rows)


def finish_docstring(cls) -> None:
    """Put the arguments table into the ``{arguments}`` place of ``cls.__doc__``."""
    table = "\n".join(_INDENT + line for line in arguments_table(cls).splitlines())
    cls.__doc__ = cls.__doc__.replace(_INDENT + "{arguments}", table)


def reference_markdown() -> str:
    """The reference part of docs/envs.md: each environment's docstring under its id."""
    from biso_cosim.envs import ENV_IDS

    parts = []
    for env_id, entry_point in ENV_IDS.items():
        module, name = entry_point.split(":")
        cls = getattr(importlib.import_module(module), name)
        body = re.sub(r"^(##+) ", r"#\1 ", inspect.cleandoc(cls.__doc__), flags=re.MULTILINE)  # one level down
        parts.append(f"## `{env_id}`\n\n{body}\n")
    return "\n".join(parts)
