"""The command line (qpcontact.cli): one parser with sub-commands; every bad flag is exit status 2
and one line, never a traceback; the same flag names everywhere; plain help texts with units;
outputs in ./<command>-out unless asked otherwise."""

from __future__ import annotations

import argparse
import re
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
