"""The `awalker` entry point: subcommand discovery, --help, and one-line user errors."""
from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from awalker_tools import cli
from awalker_tracker.errors import InputError


def test_every_command_module_registers_a_subcommand_with_help() -> None:
    names = cli.command_modules()
    assert names, "no subcommand modules found in awalker_tools.commands"
    parser = cli.build_parser()
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    # Convention: module awalker_tools/commands/<name>.py registers the subcommand <name>.
    assert sorted(subparsers.choices) == names
    for choice, sub in subparsers.choices.items():
        assert sub.format_help().strip(), choice


def test_help_runs_as_console_script() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "awalker_tools.cli", "--help"], capture_output=True, text=True, check=False
    )
    assert done.returncode == 0, done.stderr
    for name in cli.command_modules():
        assert name in done.stdout


def test_input_error_is_one_line_and_exit_code_2(monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    def failing(args: argparse.Namespace) -> int:
        raise InputError("calibration.yaml: not valid YAML (mapping values are not allowed here\n  in line 3)")

    real_build = cli.build_parser

    def build_with_failing_command() -> argparse.ArgumentParser:
        parser = real_build()
        subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        subparsers.add_parser("explode").set_defaults(func=failing)
        return parser

    monkeypatch.setattr(cli, "build_parser", build_with_failing_command)
    assert cli.main(["explode"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "awalker explode: error: calibration.yaml: not valid YAML (mapping values are not allowed here in line 3)" in err
    assert "Traceback" not in err
