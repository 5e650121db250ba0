"""The ``femstudy`` command line: one sub-command per module in :mod:`femstudy.commands`.

This is the one place that reads the environment: ``FEMSTUDY_CACHE`` (mesh cache folder,
default ``.femstudy-cache``), ``FEMSTUDY_SOLVER`` (linear solver, default auto),
``FEMSTUDY_BONES`` (calibrated bone sets, default the user's data folder); the library
takes them as explicit parameters (:class:`Settings`).

A :class:`~femstudy.errors.UserError` ends the program with one ``femstudy: error: ...``
line on stderr and exit status 2; command-line syntax errors do the same.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from dataclasses import dataclass
from pathlib import Path

from femstudy import __version__
from femstudy.errors import UserError

#: Sub-command modules, in the order ``femstudy --help`` lists them.
COMMANDS = ["run", "view", "sweep", "uncertainty", "mesh", "femur", "loads", "synth", "calibrate", "normality", "diagnose"]


@dataclass(frozen=True)
class Settings:
    """Where the library keeps things and which solver it uses, read from the environment."""

    cache_dir: Path
    solver: str
    bones_dir: Path | None

    @classmethod
    def from_environment(cls, environ=os.environ) -> "Settings":
        bones = environ.get("FEMSTUDY_BONES")
        return cls(Path(environ.get("FEMSTUDY_CACHE") or ".femstudy-cache"), environ.get("FEMSTUDY_SOLVER", "auto"),
                   Path(bones) if bones else None)


def name_mkl_library(environ=os.environ) -> None:
    """Tell pypardiso where MKL's runtime library is (its documented ``PYPARDISO_MKL_RT``),
    read from the ``mkl`` package's file list; otherwise pypardiso walks the whole environment
    for it, 0.2 s for every solver object it makes."""
    if "PYPARDISO_MKL_RT" in environ:
        return
    from importlib.metadata import PackageNotFoundError, files
    try:
        found = [f.locate() for f in files("mkl") or () if f.name.startswith("libmkl_rt")]
    except PackageNotFoundError:
        return
    found = [path for path in found if path.exists()]
    if found:
        environ["PYPARDISO_MKL_RT"] = str(found[0].resolve())


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
    from femstudy import console

    parser = build_parser()
    args = parser.parse_args(argv)
    if not hasattr(args, "run"):
        parser.print_help()
        return 2
    args.settings = Settings.from_environment()
    name_mkl_library()
    console.install(quiet=getattr(args, "quiet", False))
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
