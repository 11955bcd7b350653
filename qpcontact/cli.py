"""The ``qpcontact`` command: one subcommand per job, each a ``main(argv)`` in its own module.

Subcommands are imported only when called, so a missing optional dependency of one job does not
break the others.
"""

from __future__ import annotations

import importlib
import sys

#: subcommand -> (module, one-line help). Each module has ``main(argv: list[str]) -> int``.
COMMANDS = {
    "demo": ("qpcontact.studies.demo", "resolve a small scene with every installed solver and print a table"),
    "compare": ("qpcontact.studies.compare", "solver comparison: error against run time on colony scenes"),
    "stability": ("qpcontact.studies.stability", "run every solver on the catalogue of stiff and extreme cases"),
    "simulate": ("qpcontact.colony.simulate", "grow a colony, save snapshots and pictures"),
    "bench": ("qpcontact.studies.bench", "time each phase of a step at colony scale"),
}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in COMMANDS:
        width = max(map(len, COMMANDS))
        lines = [f"  {name:<{width}}  {help_}" for name, (_, help_) in COMMANDS.items()]
        print("usage: qpcontact COMMAND [options]   (qpcontact COMMAND --help for its options)\n\ncommands:\n" + "\n".join(lines))
        if argv and argv[0] not in ("-h", "--help"):
            print(f"\nqpcontact: unknown command {argv[0]!r}", file=sys.stderr)
            return 2
        return 0
    module = importlib.import_module(COMMANDS[argv[0]][0])
    return int(module.main(argv[1:]) or 0)


if __name__ == "__main__":
    sys.exit(main())
