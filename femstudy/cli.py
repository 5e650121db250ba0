"""The ``femstudy`` command line: one sub-command per module in :mod:`femstudy.commands`.

A :class:`~femstudy.errors.UserError` ends the program with one ``femstudy: error: ...``
line on stderr and exit status 2; command-line syntax errors do the same.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from femstudy import __version__
from femstudy.errors import UserError

#: Sub-command modules, in the order ``femstudy --help`` lists them.
COMMANDS = ["run", "view", "sweep", "mesh", "femur", "loads", "synth", "calibrate", "normality", "diagnose"]


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line and exit 2, like every user error."""

    def error(self, message: str):  # noqa: D102 - argparse API
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="femstudy", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"femstudy {__version__}")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND", parser_class=_Parser)
    for name in COMMANDS:
        importlib.import_module(f"femstudy.commands.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not hasattr(args, "run"):
        parser.print_help()
        return 2
    try:
        return int(args.run(args) or 0)
    except UserError as exc:
        print(f"femstudy: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("femstudy: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into e.g. `head`, which stopped reading
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    raise SystemExit(main())
