"""Every bad CLI value is refused before work starts: one line naming the option, exit 2, no traceback; binary
YAML and start/body descriptions outside a person's ranges are refused by their loaders (issue 57)."""
from __future__ import annotations

from pathlib import Path

import pytest

from awalker_tools import cli, pipeline, video_to_bag
from awalker_tools.commands import gaits as gaits_command
from awalker_tools.commands import synth as synth_command
from awalker_tracker.errors import InputError
from awalker_tracker.inference.filter_model import StartDescription
from awalker_tracker.model.body import BodyDescription
from awalker_tracker.vision.camera import load_calibration

TRACK = ["track", "x.bag", "--out", "run"]
CONVERT = ["convert", "--calibration", "cal.yaml", "--out", "out.bag", "--images", "cam0=frames"]
BAD = [
    (TRACK + ["--seed", "-1"], "--seed"),
    (TRACK + ["--likelihood-scale", "inf"], "--likelihood-scale"),
    (TRACK + ["--likelihood-scale", "nan"], "--likelihood-scale"),
    (TRACK + ["--particles", "1e8"], "--particles must lie in 1-200000"),
    (TRACK + ["--particles", "100000000"], "--particles must lie in 1-200000"),
    (["demo", "--bag", "x.bag", "--seed", "-1"], "--seed"),
    (["synth", "--out", "s", "--noise", "-3"], "--noise"),
    (["synth", "--out", "s", "--noise", "nan"], "--noise"),
    (["synth", "--out", "s", "--size", "100000", "100000"], "--size 100000 100000"),
    (["synth", "--out", "s", "--speed", "-1"], "--speed"),
    (["synth", "--out", "s", "--step-length", "0"], "--step-length"),
    (["gaits", "solve", "--out", "t.json", "--gravity", "nan"], "--gravity"),
    (["gaits", "solve", "--out", "t.json", "--speeds", "2:7:100000"], "at most 2000"),
    (["fitbody", "run", "--factors", "nan"], "--factors"),
    (["replay", "x.bag", "--lockstep", "--ack-timeout", "nan"], "ack_timeout"),
    (CONVERT + ["--fps", "1e-9"], "--fps must lie in 0.1-10000 frames/s, got 1e-09"),
    (CONVERT + ["--fps", "0"], "--fps must lie in 0.1-10000"),
    (CONVERT + ["--fps", "-25"], "--fps must lie in 0.1-10000"),
    (CONVERT + ["--fps", "nan"], "--fps must lie in 0.1-10000"),
    (CONVERT + ["--fps", "inf"], "--fps must lie in 0.1-10000"),
    (CONVERT + ["--fps", "25", "--start-time", "-5"], "--start-time must lie in 0-2147483648 s"),
    (CONVERT + ["--fps", "25", "--start-time", "nan"], "--start-time must lie in 0-2147483648 s"),
    (CONVERT + ["--fps", "25", "--start-time", "1e10"], "--start-time must lie in 0-2147483648 s"),
    (CONVERT + ["--timestamps", "stamps_1e10.txt"], "stamps_1e10.txt:2: stamp 1e+10 s: expected seconds since 1970 "
                                                     "below 2147483648"),
]
#: Input files the bad commands read (written before each; a bad value must be refused before their work).
INPUTS = {"stamps_1e10.txt": "0\n1e10\n"}


@pytest.mark.parametrize("argv, needle", BAD, ids=[" ".join(a[:1] + a[-2:]) for a, _ in BAD])
def test_bad_value_is_one_line_exit_2(argv: list[str], needle: str, tmp_path: Path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(tmp_path)
    for name, text in INPUTS.items():
        (tmp_path / name).write_text(text)
    # the work itself: reaching any of it means the value was not checked first
    for target, name in ((pipeline, "run_tracking"), (synth_command, "synthesise"),
                         (gaits_command.cyclic_gaits, "solve_grid"), (video_to_bag, "load_calibration")):
        monkeypatch.setattr(target, name, lambda *a, **k: pytest.fail(f"{name} reached"))
    rc = cli.main(argv)
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert rc == 2, err
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"awalker {argv[0]}: error: ") and needle in lines[0], lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(INPUTS)       # nothing written


@pytest.mark.parametrize("load, what", [(StartDescription.from_yaml, "start description"),
                                        (BodyDescription.from_yaml, "body description"),
                                        (load_calibration, "calibration file")])
def test_binary_yaml_names_the_file(load, what: str, tmp_path: Path) -> None:
    path = tmp_path / "photo.yaml"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe" * 10)
    with pytest.raises(InputError) as info:
        load(path)
    message = str(info.value)
    assert message.startswith(f"{path}: not a text file") and what in message and "\n" not in message


START = {"frame": 5, "position": [0.0, 0.0], "heading": 0.0, "speed": 1.3, "step_length": 0.7}


@pytest.mark.parametrize("change, needle", [
    ({"speed": 10.0}, "start.speed 10 m/s: expected a walking speed, 0-3 m/s"),
    ({"step_length": 10.0}, "start.step_length 10 m: expected a person's step, 0.1-1.5 m"),
    ({"position": [1e9, 0.0]}, "expected within 1000 m"),
    ({"frame": None}, "start is missing frame"),
])
def test_start_outside_a_persons_range(change: dict, needle: str) -> None:
    start = {k: v for k, v in {**START, **change}.items() if v is not None}
    text = "start: {" + ", ".join(f"{k}: {v}" for k, v in start.items()) + "}\n"
    with pytest.raises(InputError, match=needle.replace(".", r"\.")):
        StartDescription.from_yaml_text(text, "s.yaml")
    assert StartDescription.from_yaml_text("start: {" + ", ".join(f"{k}: {v}" for k, v in START.items()) + "}\n",
                                           "s.yaml").speed == 1.3


@pytest.mark.parametrize("body, needle", [
    ("upper_leg_length: 5.0, lower_leg_length: 5.0", "leg length (upper + lower leg + ankle height + sole) 10.1 m: "
                                                     "expected a person's, 0.4-1.4 m"),
    ("ankle_height: 2.0", "ankle_height 2 m: expected a person's, 0.02-0.2 m"),
    ("torso_length: 3.0", "height 4.18 m: expected a person's, 0.8-2.6 m"),
])
def test_body_outside_a_persons_range(body: str, needle: str) -> None:
    with pytest.raises(InputError) as info:
        BodyDescription.from_yaml_text("body: {" + body + "}\n", "b.yaml")
    assert str(info.value) == f"b.yaml: body {needle}"
    assert BodyDescription.from_yaml_text("body: {upper_leg_length: 0.45}\n", "b.yaml").upper_leg_length == 0.45
