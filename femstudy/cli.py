"""The ``femstudy`` command line: one sub-command per module in :mod:`femstudy.commands`.

This is the one place that reads the environment: ``FEMSTUDY_CACHE`` (mesh cache folder,
default ``.femstudy-cache``), ``FEMSTUDY_SOLVER`` (linear solver, default auto),
``FEMSTUDY_BONES`` (calibrated bone sets, default the user's data folder),
``FEMSTUDY_LOGS`` (where the traceback of a bug is written, default the user's log folder);
the library takes them as explicit parameters (:class:`Settings`).

No traceback reaches the user. A :class:`~femstudy.errors.UserError`, a command-line syntax
error, and a failure of the machine the user can act on (no memory, a full or read-only disk,
a permission) end the program with one ``femstudy: error: ...`` line on stderr and exit
status 2. Anything else is a bug: one ``femstudy: internal error: ...`` line naming the log
file that holds the traceback (a forked process's included), and exit status 1.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import time
import traceback
import warnings
from dataclasses import dataclass
from pathlib import Path

from femstudy import __version__
from femstudy.errors import UserError, environment_message

#: Sub-command modules, in the order ``femstudy --help`` lists them.
COMMANDS = ["run", "view", "sweep", "uncertainty", "mesh", "femur", "loads", "synth", "calibrate", "normality", "diagnose"]


@dataclass(frozen=True)
class Settings:
    """Where the library keeps things and which solver it uses, read from the environment."""

    cache_dir: Path
    solver: str
    bones_dir: Path | None
    log_dir: Path | None = None

    @classmethod
    def from_environment(cls, environ=os.environ) -> "Settings":
        bones, logs = environ.get("FEMSTUDY_BONES"), environ.get("FEMSTUDY_LOGS")
        return cls(Path(environ.get("FEMSTUDY_CACHE") or ".femstudy-cache"), environ.get("FEMSTUDY_SOLVER", "auto"),
                   Path(bones) if bones else None, Path(logs) if logs else None)


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line and exit 2, like every user error."""

    def error(self, message: str):  # noqa: D102 - argparse API
        self.exit(2, f"femstudy: error: {message} (see {self.prog} --help)\n")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every sub-command, or of ``command`` alone when it names one: only its module
    is imported then (importing all of them costs about 0.8 s of CPU, more than a small command)."""
    parser = _Parser(prog="femstudy", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"femstudy {__version__}")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND", parser_class=_Parser)
    for name in [command] if command in COMMANDS else COMMANDS:
        importlib.import_module(f"femstudy.commands.{name}").register(sub)
    return parser


def write_crash_log(exc: BaseException, argv: list[str], log_dir: Path | None = None) -> Path | None:
    """Write ``exc``'s traceback (with its causes: a forked process's traceback is one) to a
    new file in ``log_dir`` (default: the user's log folder, else the temporary folder);
    return its path, or None when no folder takes it."""
    import tempfile

    text = (f"femstudy {__version__}, {time.strftime('%Y-%m-%d %H:%M:%S')}\n"
            f"command: femstudy {' '.join(argv)}\n\n" + "".join(traceback.format_exception(exc)))
    folders = [log_dir] if log_dir is not None else []
    try:
        import platformdirs

        folders.append(platformdirs.user_log_path("femstudy"))
    except ImportError:
        pass
    folders.append(Path(tempfile.gettempdir()))
    for folder in folders:
        try:
            folder.mkdir(parents=True, exist_ok=True)
            path = folder / f"femstudy-crash-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.log"
            path.write_text(text, encoding="utf-8")
            return path
        except OSError:
            continue
    return None


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text.splitlines()[0]}" if text else type(exc).__name__


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    settings = None
    try:
        from femstudy import console

        parser = build_parser(next((a for a in argv if not a.startswith("-")), None))
        args = parser.parse_args(argv)
        if not hasattr(args, "run"):
            parser.print_help()
            return 2
        args.settings = settings = Settings.from_environment()
        # numpy's floating-point RuntimeWarnings are two lines each of library internals; what
        # they warn of (an overflow, a NaN) is judged by femstudy's own checks (docs/checks.md)
        warnings.simplefilter("ignore", RuntimeWarning)
        console.install(quiet=getattr(args, "quiet", False))
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
    except Exception as exc:  # noqa: BLE001 - the one place every failure is turned into a line
        message = environment_message(exc)
        if message is not None:
            print(f"femstudy: error: {message}", file=sys.stderr)
            return 2
        log = write_crash_log(exc, argv, settings.log_dir if settings else None)
        where = f"the traceback is in {log}" if log else "no log folder could be written"
        print(f"femstudy: internal error: {_first_line(exc)} (a bug in femstudy; {where})", file=sys.stderr)
        return 1


if __name__ == "__main__":
    raise SystemExit(main())
