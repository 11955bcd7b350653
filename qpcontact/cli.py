"""The ``qpcontact`` command: one parser with a sub-command per job.

Each sub-command is a module with ``add_arguments(parser)`` and ``run_command(args) -> int``
(:mod:`qpcontact.arguments`); only the module of the command given is imported, so a missing
optional dependency of one job does not break the others, and ``qpcontact --help`` lists them
all. Exit status: 0 done; 1 the job failed (a solver, a step); 2 a bad command line (one line on
stderr); 3 a ``simulate`` run that stopped at ``--max-steps`` short of ``--cells``; 128 + N stopped
by signal N after saving what was done (130 for Ctrl-C, 143 for SIGTERM). ``qpcontact``
without a command prints the help on stderr and exits with 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from . import __version__
from .arguments import Parser, exit_status, run_checked

#: sub-command -> (module, one-line help). Each module has ``add_arguments(parser)`` and ``run_command(args)``.
COMMANDS = {
    "demo": ("qpcontact.studies.demo", "resolve a small scene with every installed solver and print a table"),
    "simulate": ("qpcontact.simulation.simulate", "grow a colony: snapshots, history, pictures, ParaView files"),
    "compare": ("qpcontact.studies.compare", "solver comparison: error against run time on colony scenes"),
    "stability": ("qpcontact.studies.stability", "run every solver on the catalogue of stiff and extreme cases"),
    "bench-grown": ("qpcontact.studies.grown", "time to grow a colony from one cell, and one step of a grown colony, "
                    "for each step kind (the benchmark that counts)"),
    "bench": ("qpcontact.studies.bench", "time each phase of a step on colony snapshots"),
    "sweep": ("qpcontact.ensembles.sweep", "replicates and parameter sweeps of colony runs, as tasks on Dask"),
    "table": ("qpcontact.io.tables", "a snapshot's cells, or a run's time series, as a CSV or Parquet table"),
    "plot": ("qpcontact.simulation.picture", "draw a saved snapshot again as its run drew colony.png"),
    "import-cellmodeller": ("qpcontact.io.cellmodeller", "read a CellModeller state (its pickles) into a snapshot "
                            "that simulate --start continues"),
}


def build_parser(command: str | None = None) -> Parser:
    """The parser; the options of ``command`` (if given) are added by its module."""
    parser = Parser(prog="qpcontact", description="Contact resolution between rod-shaped cells as a constrained QP.",
                    epilog="Run 'qpcontact COMMAND --help' for the options of a command.")
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
