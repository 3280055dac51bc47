"""When the person leaves the view the track ends, no step is invented, and the next person gets a track of their
own (inference/visibility.py through `awalker track`, `eval` and the posterior topic).

The walks are rendered by the synthetic scene (our own body, one camera); when the person leaves is read off the
ground truth with the visibility rule itself (the pelvis and half the markers inside the image), so these tests
check the tracker's decision and its outputs, not the rule's thresholds."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from awalker_tools import evaluation
from awalker_tools.cli import main
from awalker_tracker.inference.visibility import LEFT_EVERY_VIEW, NOT_SUPPORTED, ViewConfig
from awalker_tracker.model.body import MARKER_NAMES
from awalker_tracker.vision.camera import load_calibration

from bag_helpers import isolated_ros, walks_bag  # noqa: F401  (autouse fixture)

RATE = 30.0
END_WITHIN_FRAMES = int(0.5 * RATE)     # the track ends within 0.5 s of the person leaving
EARLY_FRAMES = int(0.2 * RATE)          # ... or a little before, where the estimated body leaves the image first
PELVIS = MARKER_NAMES.index("pelvis")


def track(bag: Path, out: Path) -> dict:
    assert main(["track", str(bag), "--out", str(out), "--particles", "2000", "--no-fit-body", "--no-overlay",
                 "--auto-start", "--seed", "0"]) == 0
    return yaml.safe_load((out / "run.yaml").read_text())


def truth_in_view(sequence: Path) -> tuple[np.ndarray, np.ndarray]:
    """Frames of the truth and whether its body was in view (pelvis and ViewConfig's share of the markers inside the
    image)."""
    truth = evaluation.read_poses_csv(sequence / "ground_truth.csv")
    (camera,) = load_calibration(sequence / "calibration.yaml")
    inside = camera.in_image(truth.markers)                       # (F, M)
    return truth.frames, inside[:, PELVIS] & (inside.mean(axis=1) >= ViewConfig().min_inside_fraction)


def gait_rows(run: Path) -> list[dict]:
    with open(run / "gait.csv") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def side(tmp_path_factory) -> tuple[Path, Path, dict]:
    """A person walks out of the picture at its right edge; a second walker comes in from there a second later
    and walks back across."""
    sequence = tmp_path_factory.mktemp("side")
    bag = walks_bag(sequence, [((-2.2, 0.0), 0.0, 150, 1.3), ((4.3, 0.6), np.pi, 150, 1.2)],
                    (0.0, -4.8, 1.4), (0.0, 0.0, 0.9))
    run = tmp_path_factory.mktemp("side_run") / "run"
    return sequence, run, track(bag, run)


@pytest.fixture(scope="module")
def away(tmp_path_factory) -> tuple[Path, Path, dict]:
    """A person walks away from a camera looking down from 3.5 m, out of the top of its picture."""
    sequence = tmp_path_factory.mktemp("away")
    bag = walks_bag(sequence, [((0.0, -1.0), np.pi / 2, 240, 1.0)], (0.0, -3.0, 3.5), (0.0, 0.5, 0.0))
    run = tmp_path_factory.mktemp("away_run") / "run"
    return sequence, run, track(bag, run)


def left_at(frames: np.ndarray, in_view: np.ndarray, after: int) -> int:
    """The first frame after ``after`` with the truth out of view."""
    return int(frames[(frames > after) & ~in_view][0])


def test_leaving_at_the_side_ends_the_track_and_the_next_person_gets_their_own(side):
    sequence, run, record = side
    frames, in_view = truth_in_view(sequence)
    first, second = record["tracks"]           # exactly two tracks
    left = left_at(frames, in_view, first["first_frame"])
    # (the walker a little behind the person stays inside the image, on nobody: no longer supported)
    assert first["ended"]["reason"] in (LEFT_EVERY_VIEW, NOT_SUPPORTED)
    assert left - EARLY_FRAMES <= first["ended"]["frame"] <= left + END_WITHIN_FRAMES, (left, first)
    assert first["last_frame"] == first["ended"]["frame"]
    # the second walker is found once wholly in view, and followed
    assert second["first_frame"] > first["ended"]["frame"] and second["ended"] is None
    poses = evaluation.read_poses_csv(run / "poses.csv")
    truth = evaluation.read_poses_csv(sequence / "ground_truth.csv")
    at = {int(f): i for i, f in enumerate(truth.frames)}
    later = poses.frames >= second["first_frame"]
    gap = [np.linalg.norm(poses.markers[i, PELVIS, :2] - truth.markers[at[int(f)], PELVIS, :2])
           for i, f in zip(np.nonzero(later)[0], poses.frames[later])]
    assert np.median(gap) < 0.4, np.median(gap)
    # no pose is published for anybody between the end and the second start
    assert not np.any((poses.frames > first["ended"]["frame"]) & (poses.frames < second["first_frame"]))
    summary = evaluation.read_summary_csv(run / "summary.csv")
    assert set(summary["track"].tolist()) == {1, 2}
    assert summary["frame"][summary["track"] == 1].max() == first["ended"]["frame"]
    assert summary["in_view"][summary["frame"] == first["ended"]["frame"]][0] == 0
    assert set(summary["cameras_in_view"][summary["in_view"] > 0].tolist()) == {"cam0"}


def test_steps_after_the_person_left_are_not_counted(side):
    sequence, run, record = side
    frames, in_view = truth_in_view(sequence)
    first = record["tracks"][0]
    left = left_at(frames, in_view, first["first_frame"])
    rows = gait_rows(run)
    assert {r["track"] for r in rows} == {"1", "2"}
    assert all(int(r["frame"]) < left for r in rows if r["track"] == "1")
    assert all(int(r["frame"]) >= record["tracks"][1]["first_frame"] for r in rows if r["track"] == "2")
    summary = json.loads((run / "gait.json").read_text())
    assert [t["track"] for t in summary["tracks"]] == [1, 2]
    assert sum(t["steps"] for t in summary["tracks"]) == len(rows)
    assert summary["steps"] == max(t["steps"] for t in summary["tracks"])
    # the live gait topic: only steps seen, numbered per track
    from awalker_tools.bagio import SequenceReader

    with SequenceReader(run / "result.bag") as reader:
        posteriors = [msg for _, _, _, msg in reader.messages(["/awalker/posterior"])]
        live = [msg for _, _, _, msg in reader.messages(["/awalker/gait_steps"])]
    tracks = [int(m.track_id) for m in posteriors]
    assert tracks == sorted(tracks) and set(tracks) == {1, 2}
    assert not posteriors[tracks.index(2) - 1].person_in_view      # track 1's last frame: out of view
    assert all(int(m.frame_index) < left or int(m.frame_index) >= record["tracks"][1]["first_frame"] for m in live)


def test_eval_scores_only_frames_in_view(side):
    sequence, run, _ = side
    assert main(["eval", str(run), "--truth", str(sequence / "ground_truth.csv")]) == 0
    result = json.loads((run / "eval.json").read_text())
    summary = evaluation.read_summary_csv(run / "summary.csv")
    out_of_view = int(np.sum(summary["in_view"] == 0))
    assert out_of_view > 0 and result["frames_out_of_view_left_out"] == out_of_view
    assert result["absolute_mm"]["frames"] == len(summary["frame"]) - out_of_view


def test_walking_away_out_of_the_picture_ends_the_track(away):
    sequence, run, record = away
    frames, in_view = truth_in_view(sequence)
    (only,) = record["tracks"]
    left = left_at(frames, in_view, only["first_frame"])
    assert only["ended"]["reason"] in (LEFT_EVERY_VIEW, NOT_SUPPORTED)
    assert left - EARLY_FRAMES <= only["ended"]["frame"] <= left + END_WITHIN_FRAMES, (left, only)
    assert all(int(r["frame"]) < left for r in gait_rows(run))
