"""The ``biso-cosim`` command line.

Each sub-command lives in its own module of this package with a ``register(subparsers)``
function that adds its parser and sets ``func`` (called with the parsed arguments, returns
an exit code). Modules are imported only when the parser is built, and heavy imports
(MuJoCo, numba kernels) happen inside ``func``, so ``biso-cosim --help`` stays quick.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from biso_cosim import __version__

# Sub-command modules, in the order they appear in --help.
COMMANDS = ("run", "estimate", "compare", "routes", "reproduce", "sensor", "fmu")


class UserError(Exception):
    """A problem with the user's input: printed as one line, exit code 2, no traceback."""


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
    except (UserError, ValueError, TypeError, KeyError, FileNotFoundError) as exc:
        # Input problems (the message names the argument): one line, no traceback. A command
        # that has checked its input and started the real work sets args.running, after
        # which an exception is a bug and keeps its traceback.
        if getattr(args, "running", False) and not isinstance(exc, UserError):
            raise
        message = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"biso-cosim {args.command}: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
