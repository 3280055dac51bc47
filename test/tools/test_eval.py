"""Evaluation metrics and `awalker eval` on hand-made trajectories with known errors."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from awalker_tracker.errors import InputError
from awalker_tracker.inference import gait_events
from awalker_tools import evaluation
from awalker_tools.cli import main
from awalker_tools.evaluation import PoseTrack

NAMES = ("pelvis", "thorax", "head", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
         "right_ankle", "left_heel", "right_heel", "left_toe", "right_toe")
FRAMES = 30


def walking_truth() -> PoseTrack:
    """A stylised walk at 1 m/s, 30 fps: left foot planted for frames 0-14, right for 15-29."""
    t = np.arange(FRAMES) / 30.0
    markers = np.zeros((FRAMES, len(NAMES), 3))
    base = {"pelvis": (0, 0, 0.95), "thorax": (0, 0, 1.35), "head": (0, 0, 1.65), "left_hip": (0, 0.1, 0.9),
            "right_hip": (0, -0.1, 0.9), "left_knee": (0.02, 0.1, 0.5), "right_knee": (0.02, -0.1, 0.5),
            "left_ankle": (0, 0.1, 0.08), "right_ankle": (0, -0.1, 0.08)}
    for name, offset in base.items():
        markers[:, NAMES.index(name)] = np.array(offset) + np.stack([t, 0 * t, 0 * t], axis=1)
    for side, y, planted in (("left", 0.1, t < 0.5), ("right", -0.1, t >= 0.5)):
        for part, dx in (("heel", -0.05), ("toe", 0.15)):
            m = NAMES.index(f"{side}_{part}")
            x_planted = (0.25 if side == "left" else 0.75) + dx
            markers[:, m, 0] = np.where(planted, x_planted, t + dx)
            markers[:, m, 1] = y
            markers[:, m, 2] = np.where(planted, 0.0, 0.1)
    stamps = 1_000_000_000 + np.arange(FRAMES) * 33_333_333
    return PoseTrack(np.arange(FRAMES), stamps, NAMES, markers)


def shifted(track: PoseTrack, names, offset_m) -> PoseTrack:
    markers = track.markers.copy()
    for n in names:
        markers[:, NAMES.index(n)] += offset_m
    return PoseTrack(track.frames, track.stamps_ns, track.marker_names, markers)


def test_translation_is_absolute_not_relative_error():
    truth = walking_truth()
    est = shifted(truth, NAMES, np.array([0.010, 0.0, 0.0]))
    errors = evaluation.marker_errors(est, truth)
    assert np.allclose(errors["absolute_mm"], 10.0)
    assert np.allclose(errors["relative_mm"], 0.0, atol=1e-9)


def test_one_knee_off_and_per_frame_statistics():
    truth = walking_truth()
    est = shifted(truth, ["left_knee"], np.array([0.0, 0.0, 0.032]))
    errors = evaluation.marker_errors(est, truth)
    assert np.allclose(errors["absolute_mm"], 32.0 / 8)       # one of the eight evaluated markers
    assert np.allclose(errors["relative_mm"], 32.0 / 8)
    assert errors["per_marker_mm"]["left_knee"] == pytest.approx(32.0)
    # error growing 1 mm per frame along y: median 14.5, mean 14.5, std of 0..29
    markers = truth.markers.copy()
    markers[:, :, 1] += (np.arange(FRAMES) * 1e-3)[:, None]
    ramp = evaluation.evaluate(PoseTrack(truth.frames, truth.stamps_ns, NAMES, markers), truth)
    assert ramp["absolute_mm"]["median"] == pytest.approx(14.5)
    assert ramp["absolute_mm"]["mean"] == pytest.approx(14.5)
    assert ramp["absolute_mm"]["std"] == pytest.approx(np.std(np.arange(FRAMES)))
    assert ramp["relative_mm"]["max"] == pytest.approx(0.0, abs=1e-9)


def test_frames_matched_by_stamp():
    truth = walking_truth()
    sub = PoseTrack(truth.frames[5:20] + 100, truth.stamps_ns[5:20], NAMES, truth.markers[5:20] + 0.003)
    errors = evaluation.marker_errors(sub, truth)
    assert len(errors["absolute_mm"]) == 15
    assert np.allclose(errors["absolute_mm"], 3.0 * np.sqrt(3))
    late = PoseTrack(truth.frames, truth.stamps_ns + 1, NAMES, truth.markers)
    with pytest.raises(InputError, match=r"share no frame stamps.*starts -0\.000 s from the estimate.*--start-time"):
        evaluation.marker_errors(late, truth)


def test_foot_skate_penetration_and_float():
    truth = walking_truth()
    clean = evaluation.foot_plausibility(truth)
    assert clean["skate_mm"]["max"] == pytest.approx(0.0) and clean["skate_mm"]["contact_pairs"] > 20
    assert clean["penetration_mm"]["max"] == 0.0 and clean["float_mm"]["max"] == 0.0
    markers = truth.markers.copy()
    heel = NAMES.index("left_heel")
    planted = np.arange(FRAMES) < 15
    markers[planted, heel, 0] += 0.004 * np.arange(15)        # slips 4 mm per frame while planted
    markers[:, :, 2] -= 0.007                                  # whole body 7 mm into the ground
    feet = evaluation.foot_plausibility(PoseTrack(truth.frames, truth.stamps_ns, NAMES, markers))
    assert feet["skate_mm"]["max"] == pytest.approx(4.0)
    assert feet["penetration_mm"]["max"] == pytest.approx(7.0)
    raised = evaluation.foot_plausibility(shifted(truth, NAMES, np.array([0, 0, 0.012])))
    assert raised["float_mm"]["mean"] == pytest.approx(12.0)


def test_a_reacquisition_jump_is_not_foot_skate():
    """The tracker re-placing the body (a re-acquisition) moves a planted foot in one frame: a slide unless
    that frame is marked replaced, and only that frame's step is left out."""
    truth = walking_truth()
    markers = truth.markers.copy()
    markers[20:, :, 0] += 0.5                                  # the whole body 0.5 m along x from frame 20 on
    jumped = PoseTrack(truth.frames, truth.stamps_ns, NAMES, markers)
    assert evaluation.foot_plausibility(jumped)["skate_mm"]["max"] == pytest.approx(500.0)
    replaced = np.arange(FRAMES) == 20
    feet = evaluation.foot_plausibility(jumped, replaced=replaced)
    assert feet["skate_mm"]["max"] == pytest.approx(0.0) and feet["skate_mm"]["replaced"] == 1
    assert feet["skate_mm"]["contact_pairs"] >= evaluation.foot_plausibility(truth)["skate_mm"]["contact_pairs"] - 4
    late = evaluation.foot_plausibility(jumped, replaced=np.arange(FRAMES) == 21)   # the wrong frame: still a slide
    assert late["skate_mm"]["max"] == pytest.approx(500.0)


def test_csv_roundtrip_and_bad_files(tmp_path):
    truth = walking_truth()
    path = tmp_path / "poses.csv"
    evaluation.write_poses_csv(path, truth)
    back = evaluation.read_poses_csv(path)
    assert back.marker_names == NAMES and np.allclose(back.markers, truth.markers, atol=1e-6)
    assert np.array_equal(back.stamps_ns, truth.stamps_ns)
    bad = tmp_path / "bad.csv"
    bad.write_text("frame,stamp,marker,x,y,z\n0,1,pelvis,0,0,0\n")
    with pytest.raises(InputError, match="stamp_ns"):
        evaluation.read_poses_csv(bad)
    bad.write_text("frame,stamp_ns,marker,x,y,z\n0,1,pelvis,0,nan,0\n")
    with pytest.raises(InputError, match=":2: non-finite"):
        evaluation.read_poses_csv(bad)
    with pytest.raises(InputError, match="no such pose file"):
        evaluation.read_poses_csv(tmp_path / "missing.csv")


def test_eval_command_writes_json_and_plots(tmp_path, capsys):
    truth = walking_truth()
    run = tmp_path / "run"
    run.mkdir()
    evaluation.write_poses_csv(tmp_path / "truth.csv", truth)
    evaluation.write_poses_csv(run / "poses.csv", shifted(truth, NAMES, np.array([0.0, 0.02, 0.0])))
    left = (np.arange(FRAMES) < 15).astype(float)
    fallen = np.zeros(FRAMES, int)
    fallen[[3, 7, 8]] = [10, 60, 51]          # of 200 particles in frame 3, of 100 in frames 7 and 8 (adaptive count):
    evaluation.write_summary_csv(run / "summary.csv", [
        {"frame": f, "stamp_ns": int(s), "speed": 1.0, "speed_std": 0.1, "stance_left_probability": left[f],
         "effective_sample_size": 100.0, "resampled": False, "heel_strike": "", "stance_leg": "left",
         "reseeded_fallen": int(fallen[f]), "particles": 100 if f in (7, 8) else 200}    # most, in 7 and 8 only
        for f, s in zip(truth.frames, truth.stamps_ns)])
    assert main(["eval", str(run), "--truth", str(tmp_path / "truth.csv")]) == 0
    out = capsys.readouterr().out
    assert "absolute" in out and "20.0" in out
    assert "121 fallen particles re-seeded over 3 frames (most of the walkers at once on 2)" in out
    result = json.loads((run / "eval.json").read_text())
    assert result["recovery"]["frames_most_walkers_fallen"] == 2
    assert result["absolute_mm"]["mean"] == pytest.approx(20.0)
    assert result["relative_mm"]["mean"] == pytest.approx(0.0, abs=1e-6)
    assert result["stance_correct_fraction"] == pytest.approx(1.0)
    assert result["truth_speed_m_s"] == pytest.approx(1.0, rel=0.05)
    assert (run / "error_over_time.png").stat().st_size > 1000
    assert (run / "speed_stance.png").stat().st_size > 1000
    # ground truth found beside the run without --truth
    evaluation.write_poses_csv(run / "ground_truth.csv", truth)
    assert main(["eval", str(run)]) == 0


def test_eval_command_errors(tmp_path, capsys):
    assert main(["eval", str(tmp_path / "nope")]) == 2
    assert "not a directory" in capsys.readouterr().err
    assert main(["eval", str(tmp_path)]) == 2
    assert "poses.csv" in capsys.readouterr().err
    evaluation.write_poses_csv(tmp_path / "poses.csv", walking_truth())
    assert main(["eval", str(tmp_path)]) == 2
    assert "no ground truth found" in capsys.readouterr().err


def test_truth_read_from_a_bag(tmp_path):
    from awalker_tools.bagio import SequenceWriter
    from awalker_tracker.vision.camera import Camera

    truth = walking_truth()
    cam = Camera.look_at("cam0", 32, 24, 30.0, np.array([0.5, -5.0, 1.0]), np.array([0.5, 0.0, 1.0]))
    bag = tmp_path / "seq.bag"
    with SequenceWriter(bag, [cam]) as writer:
        for stamp, markers in zip(truth.stamps_ns, truth.markers):
            writer.write_frame(int(stamp), {"cam0": np.zeros((24, 32, 3), np.uint8)})
            writer.write_ground_truth(int(stamp), markers)
    back = evaluation.truth_from_bag(bag)
    assert np.array_equal(back.stamps_ns, truth.stamps_ns) and np.allclose(back.markers, truth.markers)
    run = tmp_path / "run"
    run.mkdir()
    evaluation.write_poses_csv(run / "poses.csv", shifted(truth, NAMES, np.array([0.005, 0.0, 0.0])))
    assert main(["eval", str(run), "--truth", str(bag)]) == 0
    assert json.loads((run / "eval.json").read_text())["absolute_mm"]["mean"] == pytest.approx(5.0)


def test_skate_counts_only_the_stance_foot_when_known():
    truth = walking_truth()
    markers = truth.markers.copy()
    swing = NAMES.index("right_toe")
    markers[:15, swing, 2] = 0.005                        # right toe glides just above the floor ...
    track = PoseTrack(truth.frames, truth.stamps_ns, NAMES, markers)
    assert evaluation.foot_plausibility(track)["skate_mm"]["max"] > 20     # ... and counts as slip by height
    stance_left = np.arange(FRAMES) < 15                  # but the left foot is the stance foot then
    assert evaluation.foot_plausibility(track, stance_left=stance_left)["skate_mm"]["max"] == pytest.approx(0.0)


def test_walk_quality_heading_swaps_falls_and_the_last_frame():
    truth = walking_truth()
    assert np.allclose(evaluation.facing(truth, np.arange(FRAMES)), 0.0)      # walks and faces along +x
    same = evaluation.walk_quality(truth, truth)
    assert same["heading_error_deg"]["max"] < 1e-9 and same["swap_fraction"] == 0.0
    assert same["fallen_frames"] == 0 and same["off_person_frames"] == 0 and not same["end"]["off_person"]
    markers = truth.markers.copy()
    # frames 20-29: legs swapped (left knee/ankle where the right ones are and vice versa)
    for joint in ("knee", "ankle"):
        left, right = NAMES.index(f"left_{joint}"), NAMES.index(f"right_{joint}")
        markers[20:, [left, right]] = truth.markers[20:, [right, left]]
    # frames 10-14: the body faces 30 degrees left (hips turned about the pelvis)
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    for hip in ("left_hip", "right_hip"):
        h, p = NAMES.index(hip), NAMES.index("pelvis")
        d = truth.markers[10:15, h, :2] - truth.markers[10:15, p, :2]
        markers[10:15, h, :2] = truth.markers[10:15, p, :2] + d @ np.array([[c, s], [-s, c]])
    # the last 3 frames: lying 0.8 m beside the person
    pelvis = NAMES.index("pelvis")
    markers[27:, pelvis] = truth.markers[27:, pelvis] + np.array([0.0, 0.8, -0.7])
    quality = evaluation.walk_quality(PoseTrack(truth.frames, truth.stamps_ns, NAMES, markers), truth)
    assert quality["swap_fraction"] == pytest.approx(10 / FRAMES)
    heading = np.array(quality["per_frame_heading_error_deg"])
    assert np.allclose(heading[10:15], 30.0) and np.allclose(np.delete(heading, range(10, 15)), 0.0, atol=1e-6)
    assert quality["fallen_frames"] == 3 and quality["off_person_frames"] == 3
    assert quality["end"]["fallen"] and quality["end"]["off_person"]
    assert quality["end"]["pelvis_ground_error_m"] == pytest.approx(0.8)


def test_gait_is_compared_over_the_frames_the_estimate_covers():
    """An estimate that starts later than the truth (an automatic start): step times count from its first
    frame in both, so an exact estimate is off only by the walker's double-support shift
    (``gait_events.walker_strike_delay_s``) and only the covered strikes count."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "inference"))
    from test_gait_events import stylised_walk

    markers, stance, strikes = stylised_walk()
    frames = np.arange(len(markers))
    stamps = 1_000_000_000 + np.round(frames * 1e9 / 30).astype(np.int64)
    truth = PoseTrack(frames, stamps, NAMES, markers)
    late = 20                                          # the estimate begins 20 frames into the walk
    estimate = PoseTrack(frames[late:], stamps[late:], NAMES, markers[late:])
    summary = {"stamp_ns": stamps[late:], "stance_leg": np.array(["left" if s == 0 else "right" for s in stance[late:]]),
               "strike_fraction": np.full(len(frames) - late, np.nan)}
    result = evaluation.gait_comparison(estimate, truth, summary)["comparison"]
    assert result["true_strikes"] == sum(late < f for f in strikes)
    assert result["matched_strikes"] == result["true_strikes"]
    # the walker's strikes are dated late in a double support: half of one of the 0.5 s steps' earlier
    shift = gait_events.walker_strike_delay_s(0.5)
    assert result["timing_error_s_median"] == pytest.approx(shift, abs=1e-9)
    assert result["timing_bias_s_median"] == pytest.approx(-shift, abs=1e-9)      # reported early


def turned(track: PoseTrack, angle: float) -> PoseTrack:
    """The whole track turned by ``angle`` (rad) about the vertical through the origin."""
    c, s = np.cos(angle), np.sin(angle)
    markers = track.markers.copy()
    markers[..., :2] = track.markers[..., :2] @ np.array([[c, s], [-s, c]])
    return PoseTrack(track.frames, track.stamps_ns, track.marker_names, markers)


def test_marker_bias_in_the_persons_frame_and_the_error_without_it():
    truth = walking_truth()
    # upper body 30 mm high and 20 mm behind the person (who walks and faces +x)
    est = shifted(truth, ["pelvis", "thorax", "left_hip", "right_hip"], np.array([-0.020, 0.0, 0.030]))
    bias = evaluation.marker_bias(est, truth)
    assert bias["per_marker_mm"]["pelvis"] == {"along": -20.0, "left": 0.0, "up": 30.0}
    assert bias["per_marker_mm"]["left_knee"] == {"along": 0.0, "left": 0.0, "up": 0.0}
    assert bias["absolute_median_without_offsets_mm"] == pytest.approx(0.0, abs=1e-9)
    # the same walk turned to face +y: an offset towards -x is now to the person's left
    truth_y = turned(truth, np.pi / 2)
    assert np.allclose(evaluation.facing(truth_y, np.arange(FRAMES)), np.pi / 2)
    est_y = shifted(truth_y, ["left_ankle"], np.array([-0.040, 0.0, 0.0]))
    assert evaluation.marker_bias(est_y, truth_y)["per_marker_mm"]["left_ankle"] == {"along": 0.0, "left": 40.0, "up": 0.0}
    # an error that changes sign from frame to frame has no offset: nothing to take out
    markers = truth.markers.copy()
    markers[:, NAMES.index("right_knee"), 2] += np.where(np.arange(FRAMES) % 2 == 0, 0.016, -0.016)
    wobble = PoseTrack(truth.frames, truth.stamps_ns, NAMES, markers)
    result = evaluation.evaluate(wobble, truth)
    assert result["bias"]["per_marker_mm"]["right_knee"]["up"] == pytest.approx(0.0)
    assert result["bias"]["absolute_median_without_offsets_mm"] == pytest.approx(result["absolute_mm"]["median"])
    assert "mean offsets (mm, along/left/up): pelvis +0/+0/+0" in evaluation.format_table(result)


def test_view_bias_splits_the_pelvis_error_along_and_across_each_cameras_line_of_sight():
    from awalker_tracker.vision.camera import Camera

    truth = walking_truth()                     # walks along +x from the origin, 1 m/s for 1 s
    ahead = Camera.look_at("ahead", 640, 480, 500.0, np.array([6.0, 0.0, 1.5]), np.array([0.0, 0.0, 1.0]))
    beside = Camera.look_at("beside", 640, 480, 500.0, np.array([0.5, -6.0, 1.5]), np.array([0.5, 0.0, 1.0]))
    # the whole body 0.2 m behind the person (towards -x): farther from the camera ahead, to the left of the one
    # beside (which looks along +y)
    est = shifted(truth, NAMES, np.array([-0.2, 0.0, 0.0]))
    seen = evaluation.view_bias(est, truth, [ahead, beside])
    assert seen["ahead"]["depth_mm"] == pytest.approx(200.0, abs=0.1)
    assert seen["ahead"]["across_mm"] == pytest.approx(0.0, abs=0.1)
    assert seen["beside"]["across_mm"] == pytest.approx(200.0, abs=1.0)       # rays within 5 degrees of +y
    assert abs(seen["beside"]["depth_mm"]) < 10.0
    # an error that swings from nearer to farther has no mean but a size
    markers = truth.markers.copy()
    markers[:, :, 0] += np.where(np.arange(FRAMES) % 2 == 0, 0.1, -0.1)[:, None]
    swing = PoseTrack(truth.frames, truth.stamps_ns, NAMES, markers)
    result = evaluation.evaluate(swing, truth, cameras=[ahead])
    assert result["view_bias"]["ahead"]["depth_mm"] == pytest.approx(0.0, abs=0.1)
    assert result["view_bias"]["ahead"]["depth_median_abs_mm"] == pytest.approx(100.0, abs=0.1)
    assert re.search(r"pelvis seen from ahead: depth [+-]0 mm mean \(\+ farther\), 100 median size",
                     evaluation.format_table(result))
    assert evaluation.evaluate(swing, truth)["view_bias"] == {}


def stepping_off_truth(first_foot: str) -> PoseTrack:
    """A person standing still for 20 frames (30 fps), then stepping off with ``first_foot``: it lifts 0.1 m,
    moves 0.6 m forward over 15 frames and comes down at frame 35; the other foot stays where it stood."""
    frames = 50
    markers = np.zeros((frames, len(NAMES), 3))
    markers[:, NAMES.index("pelvis")] = (0.0, 0.0, 0.95)
    for side, y in (("left", 0.1), ("right", -0.1)):
        for part, dx in (("heel", -0.05), ("toe", 0.15)):
            m = NAMES.index(f"{side}_{part}")
            markers[:, m] = (dx, y, 0.0)
            if side == first_foot:
                swing = np.clip((np.arange(frames) - 20) / 15.0, 0.0, 1.0)      # 0 standing .. 1 landed
                markers[:, m, 0] = dx + 0.6 * swing
                markers[:, m, 2] = 0.1 * np.sin(np.pi * swing)
    return PoseTrack(np.arange(frames), 1_000_000_000 + np.arange(frames) * 33_333_333, NAMES, markers)


@pytest.mark.parametrize("first_foot", ["left", "right"])
def test_a_start_names_the_leg_the_person_stands_on_for_the_first_step(first_foot: str):
    """Standing still, neither foot is planted rather than the other: the start's stance leg is the one the
    person stands on while the first step swings; while that step swings, the planted foot; at the double
    support after it, not clear (None), nor while the feet move with neither planted. Marker heights do not
    decide: the standing foot's markers may rest higher than the stepping one's."""
    truth = stepping_off_truth(first_foot)
    standing_left = first_foot == "right"
    assert [evaluation.start_stance_left(truth, row) for row in (0, 10, 19)] == [standing_left] * 3
    assert evaluation.start_stance_left(truth, 27) is standing_left        # mid-swing: the planted foot
    assert evaluation.start_stance_left(truth, 45) is None                 # both down after the first strike
    both_moving = truth.markers.copy()
    both_moving[:, [NAMES.index(f"{side}_{part}") for side in ("left", "right") for part in ("heel", "toe")], 0] += (
        0.02 * np.arange(len(truth.frames)))[:, None]                     # 0.6 m/s: neither planted nor still
    assert evaluation.start_stance_left(PoseTrack(truth.frames, truth.stamps_ns, NAMES, both_moving), 5) is None
    raised = truth.markers.copy()
    for part in ("heel", "toe"):
        raised[:, NAMES.index(f"{'left' if standing_left else 'right'}_{part}"), 2] += 0.04
    lifted = PoseTrack(truth.frames, truth.stamps_ns, NAMES, raised)
    assert evaluation.start_stance_left(lifted, 0) is standing_left
    assert evaluation.start_stance_left(truth, len(truth.frames)) is None  # no such row
