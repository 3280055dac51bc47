"""`awalker track` with two cameras whose stamps differ (issue 57): images are paired into frames by nearest stamp
within --sync-tolerance of a frame (a third by default), a frame missing a camera is tracked with the other, and
the frame numbers and stamps stay those of the first camera."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from bag_helpers import isolated_ros, shift_camera, synth_walk  # noqa: F401 (isolated_ros: an autouse fixture)

from awalker_tools import evaluation
from awalker_tools.bagio import SequenceReader
from awalker_tools.cli import main

FRAMES, BACKGROUND = 10, 4
PARTICLES = "50"



@pytest.fixture(scope="module")
def two_cameras(tmp_path_factory) -> Path:
    """A 160x120 two-camera synthetic walk, 4 background frames and 10 with the person."""
    return synth_walk(tmp_path_factory, FRAMES, BACKGROUND, "--cameras", "2")


def _track(bag: Path, out: Path, *options: str) -> int:
    return main(["track", str(bag), "--out", str(out), "--particles", PARTICLES, "--no-overlay", *options])


def _check_tracked(bag: Path, out: Path) -> dict:
    """Every frame with the person tracked, with the first camera's frame numbers and stamps; run.yaml."""
    with SequenceReader(bag) as reader:
        stamps = reader.frame_stamps.tolist()
    poses = evaluation.read_poses_csv(out / "poses.csv")
    assert poses.frames.tolist() == list(range(BACKGROUND, BACKGROUND + FRAMES))
    assert poses.stamps_ns.tolist() == stamps[BACKGROUND:]
    run = yaml.safe_load((out / "run.yaml").read_text())
    assert run["frames"] == BACKGROUND + FRAMES and run["posteriors"] == FRAMES and "incomplete" not in run
    return run


def test_cameras_3_ms_apart_make_one_frame(two_cameras: Path, tmp_path: Path):
    bag = tmp_path / "apart3.bag"
    shift_camera(two_cameras, bag, "cam1", 3_000_000)
    out = tmp_path / "run"
    assert _track(bag, out) == 0
    run = _check_tracked(bag, out)
    assert run["sync_issues"] == [] and run["sync_tolerance"] == pytest.approx(1 / 3)


def test_cameras_20_ms_apart_need_a_wider_tolerance(two_cameras: Path, tmp_path: Path, capsys):
    bag = tmp_path / "apart20.bag"
    shift_camera(two_cameras, bag, "cam1", 20_000_000)
    assert _track(bag, tmp_path / "refused") == 2          # a third of a frame: each image a frame of its own
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert ("/cam1/image_raw/compressed lie a median 13.3 ms from the nearest of /cam0/image_raw/compressed, more than "
            "--sync-tolerance 0.333 of a 33.3 ms frame; pass --sync-tolerance above 0.40") in err, err
    out = tmp_path / "run"
    assert _track(bag, out, "--sync-tolerance", "0.7") == 0
    assert _check_tracked(bag, out)["sync_issues"] == []
    assert main(["track", str(bag), "--out", str(tmp_path / "bad"), "--sync-tolerance", "1"]) == 2
    assert "--sync-tolerance must lie in [0, 1) frame periods, got 1.0" in capsys.readouterr().err


def test_a_camera_missing_every_5th_frame_is_tracked_with_the_other(two_cameras: Path, tmp_path: Path):
    """Frames 4 and 9 have no cam1 image: tracked with cam0 alone (before, dropped: a time slip), their frame
    numbers kept; run.yaml's sync_issues names them."""
    bag = tmp_path / "gaps.bag"
    shift_camera(two_cameras, bag, "cam1", 0, drop_every=5)
    out = tmp_path / "run"
    assert _track(bag, out) == 0
    run = _check_tracked(bag, out)
    with SequenceReader(bag) as reader:
        stamps = reader.frame_stamps.tolist()
    assert run["sync_issues"] == [f"frame at stamp {stamps[k]} ns tracked without camera(s) cam1 (a later image of "
                                  "theirs came first)" for k in (4, 9)]
    # the leg fit pairs the recorded features the same way (a first pass reads them)
    assert main(["fitbody", str(out), "--particles", "50", "--frames", "6", "--factors", "0.95", "1.05"]) == 0


def test_a_features_thread_slower_than_the_nodes_sync_timeout_loses_no_camera(two_cameras: Path, tmp_path: Path,
                                                                              monkeypatch):
    """Offline the replay waits for every frame: cam1's features 2.5 s late for one frame (the live node's
    sync_timeout_s is 2 s) still make that frame's pair."""
    import time

    from awalker_tracker.nodes import features_node

    process = features_node.FeatureNode._process
    seen: list[int] = []

    def slow(self, msg, topic):
        if self.camera_name == "cam1":
            seen.append(1)
            if len(seen) == BACKGROUND + 3:        # the third frame with the person
                time.sleep(2.5)
        return process(self, msg, topic)

    monkeypatch.setattr(features_node.FeatureNode, "_process", slow)
    out = tmp_path / "run"
    assert _track(two_cameras, out) == 0
    assert len(seen) >= BACKGROUND + 3 and _check_tracked(two_cameras, out)["sync_issues"] == []
