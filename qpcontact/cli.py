"""The ``qpcontact`` command: one parser with a sub-command per job.

Each sub-command is a module with ``add_arguments(parser)`` and ``run_command(args) -> int``;
only the module of the command given is imported, so a missing optional dependency of one job
does not break the others, and ``qpcontact --help`` lists them all. Exit status: 0 done; 1 the job failed (a solver, a step); 2 a bad command line (one line on
stderr); 3 a ``simulate`` run that stopped at ``--max-steps`` short of ``--cells``; 128 + N stopped
by signal N after saving what was done (130 for Ctrl-C, 143 for SIGTERM). ``qpcontact``
without a command prints the help on stderr and exits with 2.

What every command shares on its command line is here too:

- :class:`Parser`: an :class:`argparse.ArgumentParser` whose errors are one line on stderr and
  exit status 2 (never a traceback, never the whole usage);
- value types that reject what no run can use, each naming the flag and the value:
  :func:`positive_int`, :func:`non_negative_int`, :func:`positive_float`,
  :func:`non_negative_float`, :func:`tolerance`, :func:`comma_list` (comma-separated lists, the one list syntax of
  every command), :func:`on_off`, :func:`output_folder`;
- :func:`add_output_arguments`: ``--out`` (a folder, by default ``./<command>-out/``) and
  ``--overwrite``;
- :func:`run_standalone`: a command's ``main(argv)`` (``python -m`` and the tests) with the same
  parser as ``qpcontact COMMAND``; :func:`run_checked`: a qpcontact error a command raises before
  its work is one line and exit status 2.

Standard library only; the wings' commands import their helpers from here (it imports only
:mod:`qpcontact.errors`, and :mod:`qpcontact` itself only when the parser is built).
"""

from __future__ import annotations

import argparse
import importlib
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from .errors import QPContactError


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line: ``PROG: error: MESSAGE (PROG --help)``,
    exit status 2."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _number(text: str, kind: type, minimum: float, strict: bool) -> Any:
    words = f"{'an integer' if kind is int else 'a finite number'} {'>' if strict else '>='} {minimum:g}"
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be {words}, got {text!r}") from None
    if not (math.isfinite(value) and (value > minimum if strict else value >= minimum)):
        raise argparse.ArgumentTypeError(f"must be {words}, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """An integer ≥ 1."""
    return int(_number(text, int, 1, strict=False))


def non_negative_int(text: str) -> int:
    """An integer ≥ 0."""
    return int(_number(text, int, 0, strict=False))


def positive_float(text: str) -> float:
    """A finite number > 0."""
    return float(_number(text, float, 0, strict=True))


def tolerance(text: str) -> float:
    """A solver tolerance: a number in (0, 1), as the library's ``tolerance`` arguments take
    (:func:`qpcontact.solvers.check_options`), so that a command refuses what every solve of it
    would refuse, up front."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 < value < 1:  # NaN too
        raise argparse.ArgumentTypeError(f"must be a number in (0, 1), got {text!r}")
    return value


def non_negative_float(text: str) -> float:
    """A finite number ≥ 0."""
    return float(_number(text, float, 0, strict=False))


def comma_list(item: Callable[[str], Any] = str, choices: Sequence[str] | None = None) -> Callable[[str], list[Any]]:
    """A type for comma-separated lists (``--sizes 1000,10000``): each item converted by ``item``
    (and, with ``choices``, one of them); empty items and empty lists are errors."""

    def convert(text: str) -> list[Any]:
        parts = [part.strip() for part in text.split(",")]
        if not text.strip() or any(not part for part in parts):
            raise argparse.ArgumentTypeError(f"expected a comma-separated list without empty items, got {text!r}")
        if choices is not None:
            wrong = [part for part in parts if part not in choices]
            if wrong:
                raise argparse.ArgumentTypeError(f"{', '.join(map(repr, wrong))} not among {', '.join(choices)}")
        values = []
        for part in parts:
            try:
                values.append(item(part))
            except argparse.ArgumentTypeError as exc:
                raise argparse.ArgumentTypeError(f"item {part!r}: {exc}") from None
            except ValueError:
                raise argparse.ArgumentTypeError(f"item {part!r} is not a valid {getattr(item, '__name__', 'value')}") from None
        return values

    convert.__name__ = "comma-separated list"
    return convert


ON_OFF = {"on": True, "yes": True, "true": True, "off": False, "no": False, "false": False}


def on_off(text: str) -> bool:
    """``on``/``off`` (also ``yes``/``no``, ``true``/``false``); anything else is an error."""
    try:
        return ON_OFF[text.strip().lower()]
    except KeyError:
        raise argparse.ArgumentTypeError(f"expected on or off, got {text!r}") from None


def output_folder(text: str) -> Path:
    """An output folder: a path that is not empty (``--out ''`` would be the current directory)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a folder, got an empty path (use --out . for the current directory)")
    return Path(text)


def add_output_arguments(parser: argparse.ArgumentParser, command: str, what: str) -> None:
    """``--out FOLDER`` (default ``./<command>-out``) and ``--overwrite``."""
    parser.add_argument("--out", type=output_folder, default=Path(f"{command}-out"), metavar="FOLDER",
                        help=f"output folder for {what} (default: ./{command}-out); created if needed, checked "
                             "before the work starts")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the outputs of an earlier run in --out (default: refuse, so that no run is "
                             "overwritten by accident)")


def run_standalone(prog: str, add_arguments: Callable[[argparse.ArgumentParser], None],
                   run: Callable[[argparse.Namespace], int], argv: Sequence[str] | None,
                   description: str | None = None) -> int:
    """Parse ``argv`` (default ``sys.argv[1:]``) with a :class:`Parser` made by ``add_arguments``
    and call ``run``; returns the exit status (2 for a bad flag, 0 after ``--help``)."""
    parser = Parser(prog=prog, description=description)
    add_arguments(parser)
    try:
        args = parser.parse_args(sys.argv[1:] if argv is None else list(argv))
    except SystemExit as exc:
        return exit_status(exc)
    return run_checked(prog, run, args)


def run_checked(prog: str, run: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """``run(args)``; a :class:`~qpcontact.errors.QPContactError` it raises (what a command finds
    wrong before it starts its work: an unknown name, a file it cannot read, an output folder it
    cannot use) is said in one line on stderr, exit status 2."""
    try:
        return int(run(args) or 0)
    except QPContactError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2


def exit_status(exc: SystemExit) -> int:
    """The status of a ``SystemExit`` (a message given instead of a number is printed, status 1)."""
    if exc.code is None or isinstance(exc.code, int):
        return int(exc.code or 0)
    print(exc.code, file=sys.stderr)
    return 1


# ------------------------------------------------------------------------------------------
# The qpcontact command
# ------------------------------------------------------------------------------------------
#: sub-command -> (module, one-line help). Each module has ``add_arguments(parser)`` and ``run_command(args)``.
COMMANDS = {
    "demo": ("qpcontact.studies.demo", "resolve a small scene with every installed solver and print a table"),
    "simulate": ("qpcontact.simulation.simulate", "grow a colony: snapshots, history, pictures, ParaView files"),
    "compare": ("qpcontact.studies.compare", "solver comparison: error against run time on colony scenes"),
    "stability": ("qpcontact.studies.stability", "run every solver on the catalogue of stiff and extreme cases"),
    "bench-grown": ("qpcontact.studies.grown", "time to grow a colony from one cell, and one step of a grown colony, "
                    "for each step kind (the benchmark that counts)"),
    "bench": ("qpcontact.studies.bench", "time each phase of a step on colony snapshots"),
    "convergence": ("qpcontact.studies.convergence", "the colony's statistics against run time as the step shrinks, "
                    "over seeds: the error of a step size"),
    "sweep": ("qpcontact.ensembles.sweep", "replicates and parameter sweeps of colony runs, as tasks on Dask"),
    "table": ("qpcontact.io.tables", "a snapshot's cells, or a run's time series, as a CSV or Parquet table"),
    "plot": ("qpcontact.simulation.picture", "draw a saved snapshot again as its run drew colony.png"),
    "import-cellmodeller": ("qpcontact.io.cellmodeller", "read a CellModeller state (its pickles) into a snapshot "
                            "that simulate --start continues"),
    "cellmodeller": ("qpcontact.cellmodeller.run", "run a CellModeller model script unchanged on qpcontact's physics: "
                     "simulate's run folder and CellModeller-layout pickles"),
}


def build_parser(command: str | None = None) -> Parser:
    """The parser; the options of ``command`` (if given) are added by its module."""
    parser = Parser(prog="qpcontact", description="Contact resolution between rod-shaped cells as a constrained QP.",
                    epilog="Run 'qpcontact COMMAND --help' for the options of a command.")
    from . import __version__  # (here: the wings import this module while qpcontact is being imported)

    parser.add_argument("--version", action="version", version=f"qpcontact {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    for name, (module, help_) in COMMANDS.items():
        sub = commands.add_parser(name, help=help_, description=help_, formatter_class=argparse.RawDescriptionHelpFormatter)
        if name == command:
            importlib.import_module(module).add_arguments(sub)
    return parser


def command_parser(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    """The parser of the sub-command ``name`` within :func:`build_parser`'s parser."""
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return commands.choices[name]


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    # Top-level options take no value, so the first word that is not an option is the command.
    command = next((word for word in argv if not word.startswith("-")), None)
    parser = build_parser(command if command in COMMANDS else None)
    if not argv:
        parser.print_help(sys.stderr)
        return 2
    try:
        args, unknown = parser.parse_known_args(argv)
        if args.command is None:
            parser.error("a command is required")
        if unknown:  # said by the command's parser, which names the command
            command_parser(parser, args.command).error(f"unrecognized arguments: {' '.join(unknown)}")
    except SystemExit as exc:
        return exit_status(exc)
    return run_checked(f"qpcontact {args.command}", importlib.import_module(COMMANDS[args.command][0]).run_command, args)


if __name__ == "__main__":
    sys.exit(main())
