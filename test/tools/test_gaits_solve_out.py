"""`awalker gaits solve` writes only where --out says; the packaged gait table is read-only (issue 57)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from awalker_tools import cli
from awalker_tools.commands import gaits as gaits_command
from awalker_tracker.model import cyclic_gaits

TINY = ["--speeds", "4.5:5:2", "--step-lengths", "0.65:0.7:2"]


@pytest.fixture
def no_solving(monkeypatch) -> list:
    """solve_grid replaced: a refused command must not reach it."""
    calls: list = []
    monkeypatch.setattr(cyclic_gaits, "solve_grid", lambda *a, **k: calls.append(a) or pytest.fail("solved"))
    return calls


def one_error(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "error:" in line]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_the_packaged_table_is_never_written(no_solving, capsys) -> None:
    table = gaits_command.PACKAGED_TABLE
    assert table.is_file() and table.is_relative_to(gaits_command.PACKAGE_DIR)
    before = table.read_bytes()
    for extra in (["--force"], []):
        assert cli.main(["gaits", "solve", "--out", str(table), *extra, *TINY]) == 2
        line = one_error(capsys)
        assert "--out" in line and ("read-only" in line if extra else "exists already" in line)
    # a new file anywhere in the package is refused too
    assert cli.main(["gaits", "solve", "--out", str(table.parent / "new_table.json"), *TINY]) == 2
    assert "inside the installed package" in one_error(capsys)
    assert not (table.parent / "new_table.json").exists()
    assert table.read_bytes() == before and no_solving == []


def test_default_out_is_a_new_file_in_the_current_folder(tmp_path: Path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(tmp_path)
    before = gaits_command.PACKAGED_TABLE.read_bytes()
    assert cli.main(["gaits", "solve", *TINY]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["out"] == gaits_command.DEFAULT_OUT and summary["points"] == 4
    table = cyclic_gaits.GaitTable.load(tmp_path / gaits_command.DEFAULT_OUT)
    assert table.converged.shape == (2, 2)
    assert gaits_command.PACKAGED_TABLE.read_bytes() == before
    # a second run does not overwrite it unless told to
    assert cli.main(["gaits", "solve", *TINY]) == 2
    assert "exists already" in one_error(capsys)
