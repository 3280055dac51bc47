"""`awalker track` on bags with images it cannot decode (issue 57): a damaged image is tracked without, counted
per camera in run.yaml and the final line, and the frame numbers stay those of the stamps; a stream in an
encoding the tracker cannot read stops the run at once, and `awalker info` says so."""
from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from bag_helpers import isolated_ros, rewrite_images, synth_walk  # noqa: F401 (isolated_ros: an autouse fixture)

from awalker_tools import evaluation
from awalker_tools.bagio import IMAGE, SequenceReader
from awalker_tools.cli import main
from awalker_tools.typestore import typestore

FRAMES, BACKGROUND = 10, 4
PARTICLES = "50"



@pytest.fixture(scope="module")
def synth_bag(tmp_path_factory) -> Path:
    """A 160x120 one-camera synthetic walk, 4 background frames and 10 with the person."""
    return synth_walk(tmp_path_factory, FRAMES, BACKGROUND)


@pytest.fixture(scope="module")
def clean_run(synth_bag: Path, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("clean") / "run"
    assert main(["track", str(synth_bag), "--out", str(out), "--particles", PARTICLES, "--no-overlay"]) == 0
    return out


def _stamps(bag: Path) -> list[int]:
    with SequenceReader(bag) as reader:
        return reader.frame_stamps.tolist()


def _bag(synth_bag: Path, folder: Path, image: Any) -> Path:
    bag = folder / "walk.bag"
    folder.mkdir()
    rewrite_images(synth_bag, bag, image)
    return bag


def _damaged(bad_stamps: set[int]) -> Any:
    """Images at ``bad_stamps`` cut short (an rgb8 image of 10 bytes), the others as they were (rgb8)."""
    types = typestore().types

    def image(rgb: np.ndarray, old: Any) -> tuple[str, str, Any]:
        h, w = rgb.shape[:2]
        stamp = int(old.header.stamp.sec) * 1_000_000_000 + int(old.header.stamp.nanosec)
        data = rgb.reshape(-1)[:10] if stamp in bad_stamps else rgb.reshape(-1)
        return "", IMAGE, types[IMAGE](old.header, h, w, "rgb8", 0, 3 * w, data.copy())

    return image


def _grey16(encoding: str) -> Any:
    types = typestore().types

    def image(rgb: np.ndarray, old: Any) -> tuple[str, str, Any]:
        h, w = rgb.shape[:2]
        grey = (rgb.mean(axis=2) * 257).astype("<u2")
        return "", IMAGE, types[IMAGE](old.header, h, w, encoding, 0, 2 * w, grey.view(np.uint8).reshape(-1))

    return image


@pytest.mark.parametrize("bad", [(7,), (6, 7, 8, 9)])
def test_undecodable_images_are_tracked_without_and_counted(synth_bag: Path, clean_run: Path, tmp_path: Path,
                                                             bad: tuple[int, ...], capfd):
    """One damaged image, and four in a row (which stalled the lockstep replay for 600 s): every frame tracked,
    the frame numbers and stamps those of the clean bag, the count in run.yaml and the final line, overlays drawn
    for the other frames."""
    stamps = _stamps(synth_bag)
    bag = _bag(synth_bag, tmp_path / "damaged", _damaged({stamps[i] for i in bad}))
    out = tmp_path / "run"
    started = time.monotonic()
    assert main(["track", str(bag), "--out", str(out), "--particles", PARTICLES]) == 0
    assert time.monotonic() - started < 300
    err = capfd.readouterr().err          # (the nodes log to the process's stderr)
    assert f"{len(bad)} undecodable image{'s' if len(bad) > 1 else ''} tracked without (cam0 {len(bad)})" in err
    assert err.count("/cam0/image_raw: 160x120 rgb8 image with step 480 has 10 bytes") == len(bad)  # named, each
    clean = evaluation.read_poses_csv(clean_run / "poses.csv")
    poses = evaluation.read_poses_csv(out / "poses.csv")
    assert poses.frames.tolist() == clean.frames.tolist() == list(range(BACKGROUND, BACKGROUND + FRAMES))
    assert poses.stamps_ns.tolist() == clean.stamps_ns.tolist() == stamps[BACKGROUND:]
    summary, clean_summary = (evaluation.read_summary_csv(d / "summary.csv") for d in (out, clean_run))
    assert summary["frame"].tolist() == clean_summary["frame"].tolist()
    assert summary["stamp_ns"].tolist() == clean_summary["stamp_ns"].tolist()
    run = yaml.safe_load((out / "run.yaml").read_text())
    assert run["undecodable_images"] == {"cam0": len(bad)} and "incomplete" not in run
    assert run["frames"] == BACKGROUND + FRAMES and run["posteriors"] == FRAMES
    assert yaml.safe_load((clean_run / "run.yaml").read_text())["undecodable_images"] == {"cam0": 0}
    # the overlays leave out the frames without an image, and only those
    drawn = sorted(int(p.stem.split("_")[1]) for p in (out / "overlay").glob("frame_*.png"))
    assert drawn == [f for f in range(BACKGROUND, BACKGROUND + FRAMES) if f not in bad]


def test_16bit_grey_tracks_and_an_unreadable_encoding_stops_at_once(synth_bag: Path, tmp_path: Path, capsys):
    """16UC1 images track like any other; every image in an encoding the decoder refuses stops the run before it
    starts, exit 2, one line naming the topic and the encoding, and `awalker info` reports it."""
    grey = _bag(synth_bag, tmp_path / "grey16", _grey16("16UC1"))
    out = tmp_path / "run16"
    assert main(["track", str(grey), "--out", str(out), "--particles", PARTICLES, "--no-overlay"]) == 0
    run = yaml.safe_load((out / "run.yaml").read_text())
    assert run["posteriors"] == FRAMES and run["undecodable_images"] == {"cam0": 0}
    capsys.readouterr()
    refused = _bag(synth_bag, tmp_path / "float", _grey16("32FC1"))
    started = time.monotonic()
    assert main(["track", str(refused), "--out", str(tmp_path / "run32"), "--particles", PARTICLES]) == 2
    assert time.monotonic() - started < 10
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "/cam0/image_raw: unsupported image encoding '32FC1'" in err[0], err
    assert not (tmp_path / "run32" / "result.bag").exists()
    assert main(["info", str(refused)]) == 0
    info = capsys.readouterr().out
    assert "MISSING: /cam0/image_raw: unsupported image encoding '32FC1'" in info and "nothing missing" not in info
    assert main(["info", str(grey)]) == 0
    assert "nothing missing" in capsys.readouterr().out


def test_a_camera_none_of_whose_images_decode_stops_the_run(synth_bag: Path, tmp_path: Path, capsys):
    """Every image damaged (a readable encoding, unreadable data): the run stops once the first images all failed,
    exit 2 with the reason, run.yaml marking the folder incomplete."""
    bag = _bag(synth_bag, tmp_path / "all_bad", _damaged(set(_stamps(synth_bag))))
    out = tmp_path / "run"
    assert main(["track", str(bag), "--out", str(out), "--particles", PARTICLES]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    # (the feature thread may have taken an image or two more by the time the replay loop looks: 10 or more)
    seen = re.search(r"none of the first (\d+) images of camera cam0 could be decoded", err)
    assert seen is not None and int(seen.group(1)) >= 10 and "/cam0/image_raw: 160x120" in err, err
    run = yaml.safe_load((out / "run.yaml").read_text())
    assert "could be decoded" in run["incomplete"]
