"""Output folders (issue 57): a run never deletes or overwrites a file it did not write in that run.

``outdir.prepare_output_dir`` is tested directly on fake run folders; the commands (track, demo, synth, eval,
report, convert) are run through the CLI's ``main`` with their work replaced, to show the refusal comes first.
"""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from awalker_tools import cli, outdir, pipeline
from awalker_tracker.errors import InputError

LONG_NAME = "a" * 300


def assert_one_line_error(rc: int, err: str, *needles: str) -> None:
    lines = [line for line in err.splitlines() if "error:" in line]
    assert rc == 2, err
    assert len(lines) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


def previous_run(folder: Path) -> dict[str, str]:
    """A fake earlier run: its files listed in run.yaml, plus a file of the user's; returns name -> content."""
    files = {"poses.csv": "old poses", "overlay/frame_00001.png": "old frame", "first_pass/run.yaml": "a: 1\n",
             "notes.txt": "the user's notes"}
    for name, text in files.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)
    listed = sorted(n for n in files if n != "notes.txt") + ["run.yaml"]
    (folder / "run.yaml").write_text(yaml.safe_dump({"input": "x.bag", "written": listed}))
    return files


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p): (folder / p).read_bytes() for p in outdir.files_under(folder)}


# ----------------------------------------------------------------------------- prepare_output_dir


def test_new_and_empty_folders_are_taken(tmp_path: Path) -> None:
    new = tmp_path / "a" / "b"
    assert outdir.prepare_output_dir(new) == frozenset()
    assert new.is_dir()
    assert outdir.prepare_output_dir(new) == frozenset()        # empty: taken again


def test_a_folder_with_files_is_refused_and_left_alone(tmp_path: Path) -> None:
    files = previous_run(tmp_path)
    before = snapshot(tmp_path)
    with pytest.raises(InputError, match=r"--out .*: not empty .*--force"):
        outdir.prepare_output_dir(tmp_path)
    assert snapshot(tmp_path) == before
    assert (tmp_path / "notes.txt").read_text() == files["notes.txt"]


@pytest.mark.parametrize("value, needle", [("", "--out '': expected a path"),
                                           ("/proc/x", "--out /proc/x: cannot"),
                                           (LONG_NAME, "File name too long")])
def test_unusable_paths_are_one_line_errors(value: str, needle: str, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError) as info:
        outdir.prepare_output_dir(value)
    assert needle in str(info.value) and "\n" not in str(info.value)


def test_a_file_is_not_a_folder(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("mine")
    with pytest.raises(InputError, match="is a file; expected a new or empty folder"):
        outdir.prepare_output_dir(tmp_path / "f")
    assert (tmp_path / "f").read_text() == "mine"


def test_force_replaces_only_the_files_the_previous_run_listed(tmp_path: Path) -> None:
    previous_run(tmp_path)
    kept = outdir.prepare_output_dir(tmp_path, force=True, outputs=pipeline.TRACK_OUTPUTS)
    assert kept == {Path("notes.txt")}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]     # emptied folders go too
    assert (tmp_path / "notes.txt").read_text() == "the user's notes"


def test_force_keeps_a_user_file_inside_a_listed_folder(tmp_path: Path) -> None:
    """A file of the user's in a folder the run writes (overlay/) is in the way: refused, nothing removed."""
    previous_run(tmp_path)
    (tmp_path / "overlay" / "mine.png").write_text("user")
    before = snapshot(tmp_path)
    with pytest.raises(InputError, match=r"overlay/mine.png is in the way .* not listed"):
        outdir.prepare_output_dir(tmp_path, force=True, outputs=pipeline.TRACK_OUTPUTS)
    assert snapshot(tmp_path) == before
    # a folder the run does not write keeps the user's file, and the run goes ahead
    assert outdir.prepare_output_dir(tmp_path, force=True, outputs=("poses.csv",)) == {Path("overlay/mine.png"),
                                                                                       Path("notes.txt")}
    assert (tmp_path / "overlay" / "mine.png").read_text() == "user"


def test_force_refuses_an_unlisted_file_with_an_output_name(tmp_path: Path) -> None:
    (tmp_path / "poses.csv").write_text("the user's own poses")
    (tmp_path / "run.yaml").write_text("input: x.bag\n")     # an older run.yaml, listing nothing
    with pytest.raises(InputError, match="poses.csv is in the way"):
        outdir.prepare_output_dir(tmp_path, force=True, outputs=pipeline.TRACK_OUTPUTS)
    assert (tmp_path / "poses.csv").read_text() == "the user's own poses"


@pytest.mark.parametrize("entry", ["../outside.txt", "/etc/passwd"])
def test_a_listed_path_outside_the_folder_is_refused(tmp_path: Path, entry: str) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (tmp_path / "outside.txt").write_text("keep me")
    (run / "run.yaml").write_text(yaml.safe_dump({"written": [entry, "run.yaml"]}))
    with pytest.raises(InputError, match="expected a path inside"):
        outdir.prepare_output_dir(run, force=True)
    assert (tmp_path / "outside.txt").read_text() == "keep me" and (run / "run.yaml").is_file()


def test_record_written_lists_the_new_files_not_the_kept_ones(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    kept = outdir.prepare_output_dir(tmp_path, force=True, outputs=pipeline.TRACK_OUTPUTS)
    (tmp_path / "poses.csv").write_text("new")
    (tmp_path / "overlay").mkdir()
    (tmp_path / "overlay" / "frame_00000.png").write_text("new")
    assert outdir.record_written(tmp_path, kept, {"incomplete": "why"}) == [
        "overlay/frame_00000.png", "poses.csv", "run.yaml"]
    info = yaml.safe_load((tmp_path / "run.yaml").read_text())
    assert info["incomplete"] == "why" and "notes.txt" not in info["written"]
    # the next --force removes exactly those
    assert outdir.prepare_output_dir(tmp_path, force=True) == {Path("notes.txt")}
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]


def test_check_new_path(tmp_path: Path) -> None:
    (tmp_path / "taken.json").write_text("{}")
    for value, needle in (("", "expected a path"), (str(tmp_path / "taken.json"), "exists already"),
                          (str(tmp_path), "is a folder"), (str(tmp_path / "no" / "x.json"), "no folder"),
                          ("/proc/x.json", "cannot write into /proc"), (str(tmp_path / LONG_NAME), "too long")):
        with pytest.raises(InputError, match=needle):
            outdir.check_new_path(value, "--json", force=None)
    assert outdir.check_new_path(tmp_path / "taken.json", "--out", force=True) == tmp_path / "taken.json"


# ----------------------------------------------------------------------------- the commands


@pytest.fixture
def no_tracking(monkeypatch) -> list:
    """Replace the pipeline's passes: a test that reaches them would track; they record that they ran."""
    ran: list = []
    monkeypatch.setattr(pipeline, "_run_passes", lambda options, reader: ran.append(options))
    return ran


@pytest.fixture
def bag(tmp_path: Path) -> Path:
    path = tmp_path / "in" / "b.mcap"
    path.parent.mkdir()
    path.write_bytes(b"not read: the output folder is refused first")
    return path


@pytest.mark.parametrize("value, needle", [("", "--out ''"), ("/proc/x", "--out /proc/x: cannot"),
                                           ("FILE", "is a file"), ("FULL", "not empty"),
                                           (LONG_NAME, "too long")])
def test_track_refuses_an_unusable_out_before_tracking(value, needle, tmp_path, bag, no_tracking, capsys,
                                                       monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "FILE").write_text("x")
    (tmp_path / "FULL").mkdir()
    (tmp_path / "FULL" / "poses.csv").write_text("the user's")
    rc = cli.main(["track", str(bag), "--out", value])
    assert_one_line_error(rc, capsys.readouterr().err, needle)
    assert no_tracking == []
    assert (tmp_path / "FULL" / "poses.csv").read_text() == "the user's"


def test_track_force_run_lists_what_it_wrote_also_when_it_fails(tmp_path, monkeypatch, capsys) -> None:
    bag = Path(__file__).resolve().parents[2] / "bags" / "walk.bag"       # a real bag: read before the passes
    out = tmp_path / "run"
    out.mkdir()
    files = previous_run(out)

    def failing(options, reader, stop):
        (out / "calibration.yaml").write_text("new")
        raise InputError("no frame was tracked")

    monkeypatch.setattr(pipeline, "_run_passes", failing)
    rc = cli.main(["track", str(bag), "--out", str(out), "--force"])
    assert_one_line_error(rc, capsys.readouterr().err, "no frame was tracked")
    info = yaml.safe_load((out / "run.yaml").read_text())
    assert info["written"] == ["calibration.yaml", "run.yaml"]
    assert info["incomplete"] == "no frame was tracked"
    assert (out / "notes.txt").read_text() == files["notes.txt"]
    assert not (out / "poses.csv").exists()                     # the previous run's, replaced


def test_demo_never_removes_the_users_files(tmp_path, bag, monkeypatch, capsys) -> None:
    """The old demo removed the whole --out folder when it held a run.yaml (`--out .` removed the current folder)."""
    from awalker_tools.commands import eval as eval_command

    tracked: list = []
    monkeypatch.setattr(pipeline, "run_tracking", lambda options: tracked.append(options))
    monkeypatch.setattr(eval_command, "run", lambda args: 0)
    monkeypatch.chdir(tmp_path)
    files = previous_run(tmp_path)
    before = snapshot(tmp_path)
    rc = cli.main(["demo", "--bag", str(bag), "--out", "."])
    assert_one_line_error(rc, capsys.readouterr().err, "--out .: not empty")
    assert snapshot(tmp_path) == before and tracked == []
    assert cli.main(["demo", "--bag", str(bag), "--out", ".", "--force"]) == 0
    assert tracked and (tmp_path / "notes.txt").read_text() == files["notes.txt"]
    assert (tmp_path / "in" / "b.mcap").is_file()           # an unlisted folder of the user's stays
    assert not (tmp_path / "poses.csv").exists()
    # a file of the user's named like an eval output stops the demo before it tracks
    (tmp_path / "eval.json").write_text("mine")
    tracked.clear()
    rc = cli.main(["demo", "--bag", str(bag), "--out", ".", "--force"])
    assert_one_line_error(rc, capsys.readouterr().err, "eval.json is in the way")
    assert tracked == [] and (tmp_path / "eval.json").read_text() == "mine"


def test_synth_refuses_a_full_folder_and_lists_its_files(tmp_path, monkeypatch, capsys) -> None:
    from awalker_tools.commands import synth as synth_command

    made: list = []

    def fake_synthesise(config):
        made.append(config)
        (config.out_dir / "synth.bag").mkdir()
        (config.out_dir / "synth.bag" / "synth.mcap").write_text("bag")
        return {"bag": config.out_dir / "synth.bag"}

    monkeypatch.setattr(synth_command, "synthesise", fake_synthesise)
    out = tmp_path / "seq"
    out.mkdir()
    (out / "mine.txt").write_text("mine")
    rc = cli.main(["synth", "--out", str(out)])
    assert_one_line_error(rc, capsys.readouterr().err, f"--out {out}: not empty")
    assert made == []
    assert cli.main(["synth", "--out", str(out), "--force"]) == 0
    assert yaml.safe_load((out / "run.yaml").read_text())["written"] == ["run.yaml", "synth.bag/synth.mcap"]
    assert cli.main(["synth", "--out", str(out), "--force"]) == 0      # its own files replaced
    assert (out / "mine.txt").read_text() == "mine" and len(made) == 2


def test_eval_and_report_replace_only_the_runs_files(tmp_path, capsys) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / "run.yaml").write_text(yaml.safe_dump({"written": ["run.yaml"]}))
    for name in ("eval.json", "report.html"):
        (run / name).write_text("the user's")
        command = "eval" if name == "eval.json" else "report"
        rc = cli.main([command, str(run)])
        assert_one_line_error(rc, capsys.readouterr().err, f"{run / name}: exists and is not listed")
        assert (run / name).read_text() == "the user's"
    (tmp_path / "taken.json").write_text("{}")
    for value, needle in (("/proc/x.json", "--json /proc/x.json: cannot write"),
                          (str(tmp_path / "taken.json"), "exists already"), ("", "--json ''")):
        (run / "eval.json").unlink(missing_ok=True)
        rc = cli.main(["eval", str(run), "--json", value])
        assert_one_line_error(rc, capsys.readouterr().err, needle)
    # listed as the run's own (an earlier eval): eval may go on (and stops at the missing poses.csv)
    outdir.add_written(run, ["eval.json"])
    (run / "eval.json").write_text("{}")
    rc = cli.main(["eval", str(run)])
    assert_one_line_error(rc, capsys.readouterr().err, "poses.csv")


@pytest.mark.parametrize("value, needle", [("", "--out ''"), ("/proc/x", "--out /proc/x: cannot write"),
                                           ("FILE", "exists already")])
def test_convert_out(value, needle, tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "FILE").write_text("x")
    rc = cli.main(["convert", "--calibration", "cal.yaml", "--out", value, "--fps", "30", "--images", "cam0=."])
    assert_one_line_error(rc, capsys.readouterr().err, needle)
    assert (tmp_path / "FILE").read_text() == "x"


def test_eval_again_in_a_folder_without_run_yaml(tmp_path: Path) -> None:
    """A folder made by hand (no run.yaml): eval's files are listed in a run.yaml made for them, so a second
    eval may replace them, and a file of the user's is still refused."""
    outdir.add_written(tmp_path, ["eval.json"])
    assert yaml.safe_load((tmp_path / "run.yaml").read_text())["written"] == ["eval.json", "run.yaml"]
    (tmp_path / "eval.json").write_text("{}")
    outdir.check_may_write(tmp_path, ["eval.json"])
    (tmp_path / "speed_stance.png").write_text("the user's")
    with pytest.raises(InputError, match="speed_stance.png: exists and is not listed"):
        outdir.check_may_write(tmp_path, ["eval.json", "speed_stance.png"])
