"""The ``biso-cosim`` command line.

Each sub-command lives in its own module of this package with a ``register(subparsers)``
function that adds its parser and sets ``func`` (called with the parsed arguments, returns
an exit code). Modules are imported only when the parser is built, and heavy imports
(MuJoCo, numba kernels) happen inside ``func``, so ``biso-cosim --help`` stays quick.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import re
import sys
from typing import Any

from biso_cosim import __version__

# Sub-command modules, in the order they appear in --help.
COMMANDS = ("run", "estimate", "compare", "score", "campaign", "routes", "reproduce", "sensor", "fmu", "vehicle")


class UserError(Exception):
    """A problem with the user's input: printed as one line, exit code 2, no traceback."""


def parse_params(items: list[str], option: str) -> dict[str, Any]:
    """NAME=VALUE pairs; a VALUE is a Python literal (number, tuple, True, None) or else a string."""
    params: dict[str, Any] = {}
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name or not value.strip():
            raise UserError(f"{option} expects NAME=VALUE, got {item!r}")
        try:
            params[name] = ast.literal_eval(value.strip())
        except (ValueError, SyntaxError):
            params[name] = value.strip()
    return params


def split_top_level(text: str, sep: str = ",") -> list[str]:
    """Split at ``sep`` outside brackets, so that tuple values stay whole: 'a=1,k=(1,2)'."""
    parts, depth, start = [], 0, 0
    for i, ch in enumerate(text):
        depth += ch in "([{"
        depth -= ch in ")]}"
        if ch == sep and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return [s for s in (p.strip() for p in parts) if s]


def estimator_spec(text: str, option: str = "--estimator"):
    """``[LABEL=]NAME[:PARAM=VALUE,...]`` → ``EstimatorSpec``; without a label, one is made
    from the name and the values (``poisson:gyro_step=invariant`` → ``poisson_invariant``)."""
    from biso_cosim.cosim import EstimatorSpec

    head, _, tail = text.partition(":")
    label, eq, name = head.partition("=")
    if not eq:
        label, name = "", head
    name, label = name.strip(), label.strip()
    if not name or (eq and not label):
        raise UserError(f"{option} expects [LABEL=]NAME[:PARAM=VALUE,...], got {text!r}")
    params = parse_params(split_top_level(tail), f"{option} {text!r}") if tail.strip() else {}
    if not label:
        label = "_".join([name] + [re.sub(r"[^A-Za-z0-9.]+", "", str(v)) for v in params.values()])
    return EstimatorSpec(name, params, label=label)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="biso-cosim",
        description="Closed-loop tests of MEMS attitude estimation on a simulated vehicle.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"biso_cosim.cli.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:  # Ctrl-C outside a run's own handling (a run writes what it has: cli/run.py)
        print(f"biso-cosim {args.command}: interrupted", file=sys.stderr)
        return 130
    except (UserError, ValueError, TypeError, KeyError, OverflowError, OSError) as exc:
        # Input problems (the message names the argument): one line, no traceback. A command
        # that has checked its input and started the real work sets args.running, after
        # which an exception is a bug and keeps its traceback.
        if getattr(args, "running", False) and not isinstance(exc, UserError):
            raise
        message = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        if isinstance(exc, OSError) and not isinstance(exc, FileNotFoundError) and exc.filename:
            message = f"{exc.filename}: {exc.strerror or exc}"  # PermissionError, IsADirectoryError, ...
        text = " ".join(str(message).split())  # one line
        print(f"biso-cosim {args.command}: error: {text}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
