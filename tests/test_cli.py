"""The command line (qpcontact.cli): one parser with sub-commands; every bad flag is exit status 2
and one line, never a traceback; the same flag names everywhere; plain help texts with units;
outputs in ./<command>-out unless asked otherwise."""

from __future__ import annotations

import argparse
import importlib.util
import re
import shlex
from pathlib import Path

import pytest

import qpcontact as qc
from qpcontact import cli

BAD_COMMAND_LINES = [
    ["demo", "--seed", "-1"],
    ["demo", "--cells", "0"],
    ["demo", "--tolerance", "abc"],
    ["demo", "--tolerance", "5"],  # a tolerance is in (0, 1): refused up front, not by every solve
    ["demo", "--tolerance", "1"],
    ["compare", "--tolerances", "1e-3,2"],
    ["bench", "--tolerance", "1.5"],
    ["bench", "--solvers", "osqp@2"],
    ["simulate", "--seed", "-1"],
    ["simulate", "--snapshot-every", "-1"],
    ["simulate", "--cells", "2.5"],
    ["simulate", "--cfl", "nan"],
    ["simulate", "--dimensions", "4"],
    ["simulate", "--start", "x.npz", "--resume"],
    ["compare", "--tolerances", "abc"],
    ["compare", "--tolerances", "-1"],
    ["compare", "--tolerances", "1e-3,,1e-6"],
    ["compare", "--repeats", "0"],
    ["bench", "--sizes", "-5"],
    ["bench", "--dimensions", "4"],
    ["bench", "--solvers", "nosuch"],
    ["bench", "--solvers", "osqp@fast"],
    ["stability", "--scaling", "maybe"],
    ["stability", "--formulations", "linear"],
    ["stability", "--seed", "-1"],
    ["simulate", "--no-such-flag"],
    ["sweep", "--seeds", "-1"],
    ["sweep", "--vary", "growth_inertia"],
    ["sweep", "--seeds", "1", "--replicates", "2"],
    ["sweep", "--workers", "0"],
    ["frobnicate"],
]


@pytest.mark.parametrize("argv", BAD_COMMAND_LINES, ids=" ".join)
def test_a_bad_flag_is_exit_status_2_and_one_line(argv, capsys):
    assert cli.main(argv) == 2
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and "Traceback" not in err and not out, err
    assert err.startswith(f"qpcontact {argv[0]}: error: " if argv[0] in cli.COMMANDS else "qpcontact: error: ")


@pytest.mark.parametrize("argv, message", [
    (["simulate", "--start", "nosuch.npz"], "nosuch.npz: no such file"),
    (["simulate", "--start", "JUNK"], "cannot be read, truncated or corrupted (not an NPZ file)"),
    (["simulate", "--config", "nosuch.toml"], "nosuch.toml: no such file"),
    (["compare", "--scenes", "nosuch"], "unknown scene 'nosuch'"),
    (["compare", "--solvers", "nosuch"], "unknown or uninstalled solver 'nosuch'"),
    (["stability", "--cases", "nosuch"], "no case matches 'nosuch'"),
    (["stability", "--solvers", "nosuch"], "unknown solver 'nosuch'"),
])
def test_a_bad_input_file_or_name_is_exit_status_2_and_one_line_and_writes_nothing(argv, message, tmp_path, capsys,
                                                                                  monkeypatch):
    """``stability --cases nosuch`` exited 0 after 0 runs and overwrote docs/data/stability.csv."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "JUNK").write_bytes(b"j")
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["JUNK"]  # no output folder, no file


def test_bare_qpcontact_prints_the_help_and_exits_2(capsys):
    """It exited 0."""
    assert cli.main([]) == 2
    out, err = capsys.readouterr()
    assert not out and err.startswith("usage: qpcontact") and all(name in err for name in cli.COMMANDS)


def test_version(capsys):
    assert cli.main(["--version"]) == 0
    assert capsys.readouterr().out == f"qpcontact {qc.__version__}\n"


def parsers() -> dict[str, argparse.ArgumentParser]:
    """Every sub-command's parser, as ``qpcontact COMMAND`` builds it."""
    return {name: cli.command_parser(cli.build_parser(name), name) for name in cli.COMMANDS}


@pytest.mark.parametrize("name", list(cli.COMMANDS))
def test_help_is_plain_text_with_units(name, capsys):
    """Help texts came from docstrings with Sphinx markup; several numbers had no unit."""
    assert cli.main([name, "--help"]) == 0
    text = capsys.readouterr().out
    assert not re.search(r":(func|mod|class|data|attr|meth):|``", text), text
    for action in parsers()[name]._actions:
        if action.type in (float,) or getattr(action.type, "__name__", "") in ("positive_float", "non_negative_float"):
            assert re.search(r"\[[^\]]+\]", action.help or ""), f"{name} {action.option_strings}: no unit"


def test_the_same_flag_names_everywhere():
    """--dim / --dimensions / --dims and --out / --out-dir were all in use."""
    for name, parser in parsers().items():
        flags = {flag for action in parser._actions for flag in action.option_strings}
        assert not flags & {"--dim", "--dims", "--out-dir", "--output"}, name
        if name != "demo":
            assert {"--out", "--overwrite"} <= flags, name


@pytest.mark.parametrize("name", ["simulate", "compare", "stability", "bench", "sweep"])
def test_outputs_go_to_a_folder_of_the_commands_name_by_default(name):
    """stability and bench wrote into docs/ by default."""
    assert parsers()[name].parse_args([]).out == Path(f"{name}-out")


def test_list_flags_are_comma_separated():
    args = parsers()["bench"].parse_args(["--sizes", "300,1000", "--dimensions", "2,3", "--solvers", "linear,osqp/contact"])
    assert (args.sizes, args.dimensions, args.solvers) == ([300, 1000], [2, 3], ["linear", "osqp/contact"])
    args = parsers()["stability"].parse_args(["--scaling", "on,off"])
    assert args.scaling == [True, False]
    assert parsers()["compare"].parse_args(["--tolerances", "1e-3, 1e-6"]).tolerances == [1e-3, 1e-6]


# ------------------------------------------------------------------------------------------
# The command lines the documents give (issue 27, item 6: docs that cannot drift)
# ------------------------------------------------------------------------------------------
ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: Command lines a document quotes *because* they are refused now (history), each with where.
QUOTED_AS_REFUSED = {
    "qpcontact simulate --cells 10000 --solver osqp --tolerance 1e-3": "docs/colony.md, the 10k growth run (historical)",
}
#: Words a document's own example defines before its command lines use them, and what stands in.
DEFINED_BY_THE_DOCUMENT = {"--solvers pgs": "--solvers linear"}  # docs/architecture.md registers "pgs"


def documented_command_lines(text: str) -> list[str]:
    """Every ``qpcontact ...`` command line of a Markdown text: the lines of its code blocks
    (continued with a backslash, comments dropped) and its inline code spans."""
    lines = []
    for block in re.findall(r"```[a-z]*\n(.*?)```", text, re.S):
        for line in re.sub(r"\\\n\s*", " ", block).splitlines():
            line = line.strip().removeprefix("$ ")
            if line.startswith("qpcontact "):
                lines.append(line.split(" #")[0].strip())
    prose = re.sub(r"```.*?```", "", text, flags=re.S).replace("\n", " ")
    lines += [re.sub(r"\s+", " ", span).strip() for span in re.findall(r"`(qpcontact [a-z][^`]*)`", prose)]
    return lines


def all_documented_command_lines() -> dict[str, str]:
    """command line -> the first document that gives it."""
    found: dict[str, str] = {}
    for document in DOCUMENTS:
        for line in documented_command_lines(document.read_text()):
            found.setdefault(line, document.name)
    return found


def test_the_documents_command_lines_are_found():
    found = all_documented_command_lines()
    assert len(found) > 40
    assert "qpcontact simulate --pressure-growth linear --stall-pressure 40" in found  # a code block
    assert "qpcontact bench --quick" in found
    assert set(QUOTED_AS_REFUSED) <= set(found)


@pytest.mark.parametrize("line", sorted(all_documented_command_lines()))
def test_every_documented_command_line_is_accepted_by_its_parser(line, capsys):
    """Every flag and value of every command line in README.md and docs/*.md parses (a renamed
    or refused flag, a value out of range: the document drifted), except those a document quotes
    as refused, which must be refused."""
    parsed = line
    for word, stand_in in DEFINED_BY_THE_DOCUMENT.items():
        parsed = parsed.replace(word, stand_in)
    argv = shlex.split(parsed)[1:]
    parser = cli.build_parser(argv[0])
    if len(argv) == 1 and line not in QUOTED_AS_REFUSED:
        # A command named alone (the README's table of commands) names it, whatever it needs.
        assert argv[0] in cli.COMMANDS
        return
    try:
        parser.parse_args(argv)
        status = 0
    except SystemExit as exc:
        status = cli.exit_status(exc)
    err = capsys.readouterr().err
    if line in QUOTED_AS_REFUSED:
        assert status == 2, f"{QUOTED_AS_REFUSED[line]} quotes {line!r} as refused, but it parses"
    else:
        assert status == 0, f"{line!r} ({all_documented_command_lines()[line]}): {err}"


def quick_form(line: str, out: Path) -> list[str] | None:
    """A documented ``qpcontact simulate`` line made quick (4 cells, into ``out``, quiet), or None
    for a line that needs a file or a run first (--resume, --start, --config) or names a
    placeholder."""
    argv = shlex.split(line)[1:]
    if line in QUOTED_AS_REFUSED or argv[0] != "simulate" or any(a in argv for a in ("--resume", "--start", "--config", "--help")) or any(
            re.fullmatch(r"[A-Z]+", a) for a in argv):
        return None
    if "--vtk" in argv and importlib.util.find_spec("meshio") is None:  # the extra: the parse above checks the flag
        argv.remove("--vtk")
    quick, skip = [], False
    for a in argv:
        if skip:
            skip = False
            continue
        if a in ("--cells", "--out"):
            skip = True
            continue
        quick.append(a)
    return [*quick, "--cells", "4", "--out", str(out), "--quiet"]


@pytest.mark.slow
def test_every_documented_simulate_line_runs_in_a_quick_form(tmp_path, capsys):
    """The documents' ``qpcontact simulate`` lines, each to 4 cells into a folder of its own."""
    lines = [line for line in all_documented_command_lines() if quick_form(line, tmp_path) is not None]
    assert len(lines) >= 8
    for i, line in enumerate(lines):
        argv = quick_form(line, tmp_path / f"run{i}")
        assert argv is not None
        status = cli.main(argv)
        assert status == 0, f"{line!r}: {capsys.readouterr().err}"
