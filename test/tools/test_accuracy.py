"""Accuracy of `awalker synth` -> `awalker track` -> `awalker eval` against the renderer's ground truth
(issue 6 §7): monocular and two-camera straight walks, a speed change, a 75 degree turn, a
lower-body occluder and a CMU mocap render, 40 frames at 320x240, 500 particles (the settings
of `benchmarks/bench_accuracy.py --quick`). Each sequence is made and tracked once per module.

Bounds: measured over tracker seeds 0-9 (figures above BOUNDS), set at least 15 % above the worst
seen (except where a known gap fails a seed: the occluder) yet tight enough that the image
likelihood switched off, or a walker with legs 30 % too long, fails every case. Absolute errors of a single camera are dominated by depth,
which one camera observes weakly, so the relative error and the stance leg carry most of the
discrimination there.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from accuracy_helpers import pelvis_offsets, speed_error
from awalker_tools.cli import main

MOCAP = Path(__file__).resolve().parents[1] / "data" / "mocap" / "cmu_subject07"
FRAMES, BACKGROUND, SIZE, PARTICLES = 40, 5, ("320", "240"), 500
SYNTH_SEED = 1
# bounds are set from tracker seeds 0-4; run another with AWALKER_TEST_TRACK_SEED=3 pytest test/tools/test_accuracy.py
# (2026-11-25, seeds 1-4: all pass but the stop test at seed 3, whose track ends 0.54 m off the person, and the
# no-recovery control of the re-acquisition test at seed 4, 262 mm along the walk, where 300 is asked)
TRACK_SEED = int(os.environ.get("AWALKER_TEST_TRACK_SEED", "0"))

SEQUENCES = {
    "mono_straight": ["--cameras", "1"],
    "two_camera_straight": ["--cameras", "2"],
    "speed_change": ["--cameras", "1", "--speed-change"],
    "turn": ["--cameras", "1", "--turn", "75"],
    "occluder": ["--cameras", "1", "--occluder"],
    "mocap": ["--cameras", "1", "--from-mocap", str(MOCAP / "07.asf"), str(MOCAP / "07_01.amc")],
}


@dataclass(frozen=True)
class Bounds:
    """Upper bounds on mean errors over frames (mm), mean |speed error| (m/s); lower bound on the
    fraction of planted-foot frames with the stance-left probability on the right side of 0.5."""

    absolute_mm: float
    relative_mm: float
    speed_m_s: float
    stance: float


# Measured (mean absolute / mean relative mm, planted-foot stance, mean |speed error| m/s) with
# synthesis seeds 1, 2, 3 (tracker seed 0) and tracker seeds 1, 2 (synthesis seed 1), worst of five
# (commit 7d265b0: stable control prior, TrackerConfig.kappa_bar_variance 0.02, likelihood depth fix):
#   mono_straight 116/29, 0.97, 0.09    two_camera_straight 69/23, 1.00, 0.08 (likelihood averaged over cameras)
#   speed_change 136/30, 0.97, 0.20     turn 265/80, 0.93, 0.19
#   occluder 227/42, 0.97, 0.13         mocap 185/57, 0.91, 0.17
# This file's seeds (1, 0): 34/16, 56/23, 105/22, 246/72, 143/14, 91/57 mm.
# With the turn prior, recovery and per-part mean appearance (no reward for a body drawn larger), synthesis
# seed 1, tracker seeds 0-4 (mean absolute / mean relative, mm): mono_straight 36-129 / 16-27, two cameras
# 31-65 / 16-22, speed_change 46-152 / 15-26, turn 110-131 / 30-50, occluder 106-200 / 28-46, mocap 90-195 / 58-65.
# Without the image likelihood (scale 1e-6, seeds 1, 0): stance 0.58, 0.58, 0.54, 0.56, 0.58, 0.69 -> every case
# fails its stance bound. Walker legs 30 % too long in the tracker (mocap, seeds 1, 0): 615/354 mm, stance 0.56;
# with the earlier prior: relative 209, 176, 177, 226, 206, 57 mm.
# Tracker seeds 0-9 (2026-11-26, main at cce69ce; median and worst of the ten, mean absolute / mean relative mm,
# stance): mono_straight 100 / 20 (worst 214 / 34, 0.95), two cameras 47 / 18 (81 / 26, 0.95), speed_change 95 / 23
# (214 / 34, 0.89), turn 125 / 40 (205 / 79, 0.96), occluder 152 / 34 (447 / 179, 0.41 at seed 6, where the legs
# are lost behind the occluder: README "Known gaps"; seed 8: stance 0.78), mocap 173 / 52 (309 / 68, 0.84). The
# bounds before, set over seeds 0-4 with no margin, failed at four of seeds 5-9 (mono_straight 214 and 205 mm,
# speed_change stance 0.89, the automatic start 545 mm): a change that only alters the random numbers drawn fails
# them as often. Now each holds over seeds 0-9 with >= 15 % margin (stance: >= 3 frames of 37), except the
# occluder's at seed 6; without the image likelihood every case still fails its stance bound (above).
# With the tracker's step width (KinematicConfig.step_width 0.10 m; synth still draws Table 1's, the feet 0.18 m
# apart, so each ankle is drawn ~4 cm outside where the prior puts it) and the stance lean fall test, tracker seeds
# 0-9 (2026-11-26, main at d62eded): mono_straight 74 / 27 (worst 227 / 44, 0.95), two cameras 53 / 23 (100 / 32,
# 0.95), speed_change 80 / 27 (195 / 40, 0.95), turn 124 / 43 (272 / 63, 0.93; speed 0.20 m/s), occluder 129 / 36
# (245 / 47, 0.62 at seed 6), mocap 164 / 50 (319 / 76, 0.84; speed 0.216 at seed 6): absolute errors lower or the
# same, relative ones 3-10 mm higher (the drawn stance is not the prior's). The bounds moved to keep >= 15 %
# margin over these: mono_straight absolute 250 -> 265 and relative 40 -> 52, two cameras absolute 100 -> 115,
# speed_change relative 45 -> 47, mocap absolute 360 -> 370 and speed 0.2 -> 0.25. With one camera's depth-drift
# re-acquisition (recovery.RecoveryConfig.lost_distance_one_camera_m; 2026-11-26) every figure of seeds 0-9 is the
# same but the turn's at seed 2: 317 / 57 mm (was 272 / 63). During the turn the person's blob puts the feet 0.2-0.7
# m too far, the track was 0.3-0.5 m too near, and re-seeded at the blob it ends 0.96 m off (was 0.64); turn
# absolute 330 -> 365. (The feet rows of these renders' blobs, which lose the head and part of the legs, stand
# 0.8 of the body's height on most frames and do not count.)
# The occluder box stands in front of half of the walk since 2026-11-27 (synth.OCCLUDED_SHARE; it was 1.6 m wide,
# as wide as this 40-frame walk, so the legs were never seen and which one stood was the start's coin toss: seeds
# 6 and 8 lost them). Tracker seeds 0-9 (main at dc16bf2 plus the box): absolute 80/62/237/60/278/236/80/249/62/82,
# relative 38/38/23/32/37/36/33/28/24/28, stance 0.92/1.00/1.00/1.00/1.00/0.97/0.95/1.00/0.89/0.95, speed
# 0.03-0.11 m/s; the bounds 15 % above the worst (stance: 3 frames of 37 below it). Likelihood off (scale 1e-6,
# seeds 0-1): stance 0.62, 0.59.
# Two cameras with the particles' pelvis ceilings around 0.97 of the walker's hip (TrackerConfig.pelvis_ceiling,
# the default with two cameras since 2026-11-29; people walk so, where synth's walker carries the pelvis at its
# hip), tracker seeds 0-9: mean absolute median 58.6 / worst 76.0 mm, relative 25.0 / 40.7 (seed 0: the pelvis
# 38 mm low), against 51.8 / 76.3 and 25.3 / 31.4 without (the same day). 500 particles do not always find this
# walker's straight leg among the ceilings; at bench_accuracy's 15000 they do (median of seeds 0-4 24.8 mm against
# 23.9, relative 13.7 against 13.8). Relative bound 40 -> 47.
# Two cameras on maps 160 pixels wide (2 x 2 image pixels each at 320x240, features.map_downsample; 2026-11-29,
# session 19), tracker seeds 0-9: mean absolute median 47.6 / worst 70.3 mm, relative 30.6 / 38.6, stance
# 0.89-0.95 (33-35 of 37 frames), against 50.4 / 81.4, 26.2 / 39.7 and 0.89-0.95 on 4 x 4 maps the same day
# (seed 9 already 33 of 37, under the bound of 0.9 then). Stance bound 0.9 -> 0.86, a frame below the worst.
# Speed errors are against the truth's walking speed by the tracker's own definition (inference.speed: horizontal
# pelvis displacement per frame averaged over about one step); against the former truth (the pelvis chord over a
# centred second), tracker seed 0: mono_straight 0.094 -> 0.089, two cameras 0.048 -> 0.041, speed_change
# 0.063 -> 0.044, turn 0.152 -> 0.071 (the chord cuts the turn's corner), occluder 0.104 -> 0.099, mocap 0.100 ->
# 0.100 m/s. The speed bounds, set on the former, are kept.
BOUNDS = {
    "mono_straight": Bounds(265.0, 52.0, 0.18, 0.9),
    "two_camera_straight": Bounds(115.0, 47.0, 0.18, 0.86),
    "speed_change": Bounds(280.0, 47.0, 0.24, 0.8),
    # the second half of the turn is followed loosely; stance 0.85 -> 0.7 with the flow in the current
    # frame's pixels (2026-11-27, late: 0.79 at seed 0, 0.89-0.96 at seeds 1-9; before, 0.82-0.96; likelihood
    # off 0.56): 20 of its 28 planted-foot frames, two below the worst
    "turn": Bounds(365.0, 95.0, 0.28, 0.7),
    "occluder": Bounds(320.0, 44.0, 0.18, 0.8),    # the occluded stretch delays the stance switch
    # real gait: the walker's legs and feet differ from the mocap's. Since the mocap walk faces the walking
    # direction over a stride (synth, b5b794d) and the shadow model (0e43ec0, 4d2c087), tracker seeds 0-4 give
    # mean absolute 146-273 mm, relative 55-82, stance 0.78-0.97 (the bounds before, 75 mm and 0.85, held for
    # seeds 0-1 only). The stance leg is what the images decide here: with the likelihood scaled to 1e-6
    # relative 63-77 mm but stance 0.56-0.66; with no likelihood relative 69-205, stance the same.
    "mocap": Bounds(370.0, 90.0, 0.25, 0.72),
}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """name -> eval.json dict plus the planted-foot stance agreement, made on first use.

    All nodes of `awalker track` run in this process: DDS discovery off and this worker's domain,
    so concurrent runs on the machine cannot feed each other's topics."""
    done: dict[str, dict] = {}
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
        patch.setenv("ROS_DOMAIN_ID", str(60 + int(worker.removeprefix("gw") or 0)))

        def get(name: str) -> dict:
            if name not in done:
                root = tmp_path_factory.mktemp(name)
                for seed in range(SYNTH_SEED, SYNTH_SEED + 5):   # a walker that falls: the next seed
                    seq = root / f"seed{seed}"
                    code = main(["synth", "--out", str(seq), "--frames", str(FRAMES), "--background-frames",
                                 str(BACKGROUND), "--size", *SIZE, "--seed", str(seed), *SEQUENCES[name]])
                    if code == 0:
                        break
                else:
                    pytest.fail(f"{name}: awalker synth fell with every seed")
                out = root / "run"
                assert main(["track", str(seq / "synth.bag"), "--out", str(out), "--particles", str(PARTICLES),
                             "--seed", str(TRACK_SEED), "--no-overlay"]) == 0
                assert main(["eval", str(out)]) == 0
                result = json.loads((out / "eval.json").read_text())
                result["speed_error_m_s"] = speed_error(out, seq / "ground_truth.csv")
                result["sequence_dir"] = str(seq)
                result["run_dir"] = str(out)
                done[name] = result
            return done[name]

        yield get


@pytest.mark.parametrize("name", list(SEQUENCES))
def test_marker_errors_within_bounds(runs, name: str):
    result, bounds = runs(name), BOUNDS[name]
    assert result["absolute_mm"]["frames"] == FRAMES     # every frame with the person was tracked and scored
    absolute, relative = result["absolute_mm"]["mean"], result["relative_mm"]["mean"]
    assert absolute < bounds.absolute_mm, f"{name}: mean absolute error {absolute:.0f} mm"
    assert relative < bounds.relative_mm, f"{name}: mean relative error {relative:.0f} mm"


def test_two_cameras_at_320x240_track_on_maps_160_pixels_wide(runs):
    """`awalker track` hands each features node of a two-camera rig the finer maps (vision.features.map_downsample):
    2 x 2 image pixels per map pixel at these 320x240 images, where one camera keeps 4."""
    import yaml

    for name, expected in (("two_camera_straight", 2), ("mono_straight", 4)):
        run = yaml.safe_load((Path(runs(name)["run_dir"]) / "run.yaml").read_text())
        assert set(run["map_downsample"].values()) == {expected}, name


@pytest.mark.parametrize("name", list(SEQUENCES))
def test_stance_leg_posterior(runs, name: str):
    result = runs(name)
    fraction, scored = result["stance_correct_fraction"], result["stance_scored_frames"]
    assert scored >= FRAMES // 2, f"{name}: only {scored} frames with one planted foot"
    assert fraction > BOUNDS[name].stance, f"{name}: stance leg right on {100 * fraction:.0f}% of {scored} frames"


@pytest.mark.parametrize("name", list(SEQUENCES))
def test_speed_estimate(runs, name: str):
    error = runs(name)["speed_error_m_s"]
    assert error < BOUNDS[name].speed_m_s, f"{name}: mean speed error {error:.3f} m/s"


@pytest.mark.parametrize("name", ["mono_straight", "two_camera_straight"])
def test_heel_strikes_in_the_summary(runs, name: str):
    """summary.csv marks the MAP walker's heel strikes with when in the frame they happened (0-1), one per
    step: on a steady walk, a strike every ~16 frames (0.53 s at 30 Hz)."""
    from awalker_tools import evaluation

    summary = evaluation.read_summary_csv(Path(runs(name)["run_dir"]) / "summary.csv")
    struck = np.isfinite(summary["strike_fraction"])
    assert np.all((summary["strike_fraction"][struck] >= 0) & (summary["strike_fraction"][struck] < 1))
    assert abs(int(struck.sum()) - FRAMES / 16) <= 1.5


@pytest.mark.parametrize("name", list(SEQUENCES))
def test_feet_on_the_ground(runs, name: str):
    """Physics: the tracked stance foot does not slide or sink, and it stays near the floor."""
    feet = runs(name)["estimate_feet"]
    assert feet["skate_mm"]["contact_pairs"] >= FRAMES // 2
    # measured: skate mean 0.2-0.7 mm, max <= 3.9 mm; penetration 0; float mean 1.3-4.5 mm (truth: 1.3-3.6).
    # Turning: the heading turns the planted foot about its contact point, so heel and toe markers slip a
    # little, as in the truth walker (skate mean 1.5 mm, max 13.5 mm); tracker seeds 0-4: mean 1.4-2.0, max 8.3-12.6.
    # Tracker seeds 0-9 (2026-11-26): worst mean 1.18 mm (speed_change, mocap), max 7.8 (mocap); turn 2.2 and 14.6.
    # With the knees bent in stance (2026-11-27), tracker seeds 1-4: the turn's mean 1.6-2.5 mm, max 5.6-13.3
    # (the bent stance leg turns about the contact with the knee ahead of it); bound 15 % above the worst.
    mean_bound, max_bound = (2.9, 18.0) if name == "turn" else (1.5, 10.0)
    assert feet["skate_mm"]["mean"] < mean_bound and feet["skate_mm"]["max"] < max_bound
    assert feet["penetration_mm"]["max"] < 2.0
    assert feet["float_mm"]["mean"] < 8.0


@pytest.mark.parametrize("recovery", [True, False])
def test_a_track_started_beside_the_person_is_reacquired(runs, tmp_path, recovery: bool):
    """Recovery (inference/recovery.py): started 1.2 m ahead of the person along the walk (a wrong start
    description), the track is re-acquired from the image within 1 s and the body then walks with the
    person; without recovery the filter is still far ahead of them half a second in."""
    import numpy as np
    import yaml

    from awalker_tools import evaluation

    seq = Path(runs("mono_straight")["sequence_dir"])
    start = yaml.safe_load((seq / "start.yaml").read_text())
    heading = float(start["start"]["heading"])
    x, y = start["start"]["position"]
    start["start"]["position"] = [float(x + 1.2 * np.cos(heading)), float(y + 1.2 * np.sin(heading))]
    (tmp_path / "start.yaml").write_text(yaml.safe_dump(start))
    out = tmp_path / "run"
    args = ["track", str(seq / "synth.bag"), "--out", str(out), "--particles", str(PARTICLES),
            "--seed", str(TRACK_SEED), "--start", str(tmp_path / "start.yaml"), "--no-overlay"]
    assert main(args + ([] if recovery else ["--no-recovery"])) == 0
    assert main(["eval", str(out)]) == 0
    result = json.loads((out / "eval.json").read_text())
    summary = evaluation.read_summary_csv(out / "summary.csv")
    estimate = evaluation.read_poses_csv(out / "poses.csv")
    truth = evaluation.read_poses_csv(seq / "ground_truth.csv")
    absolute = evaluation.marker_errors(estimate, truth)["absolute_mm"]
    # the pelvis's error along the walk: what the wrong start got wrong, and what one camera sees well
    # (its depth error is the monocular one, with or without a wrong start)
    along = 1000.0 * np.abs(pelvis_offsets(estimate, truth)[:, :2] @ np.array([np.cos(heading), np.sin(heading)]))
    second_quarter_along = float(np.median(along[FRAMES // 4:FRAMES // 2]))   # 0.33-0.67 s after the start
    last_half_along = float(np.median(along[FRAMES // 2:]))
    last_half = float(np.median(absolute[FRAMES // 2:]))
    # measured (synthesis seed 1, tracker seeds 0-4, swing knee rest 2.5 psi_hip; medians in mm, along the
    # walk over frames 10-20 / over the last half, and all markers over the last half): with recovery 16-63 /
    # 14-60 / 284-804 (re-acquired at frame 11, 0.2 s after the start); without 805-966 / 265-443 / 264-482:
    # without recovery the likelihood walks the filter back to the person by itself, over a second (the
    # paper's swing knee, 5 psi_hip: it stayed > 431 mm off), so the comparison is made while recovery
    # should already have acted. All markers' error is one camera's depth, which a re-acquisition does
    # not fix; above 1000 mm the re-acquisition put the body at the wrong depth.
    if recovery:
        fired = summary["frame"][summary["reacquired"] > 0]
        assert result["recovery"]["reacquisitions"] >= 1 and fired.size
        assert fired[0] - summary["frame"][0] <= 30, f"re-acquired only at frame {fired[0]}"
        assert second_quarter_along < 200.0, \
            f"{second_quarter_along:.0f} mm off along the walk 0.33-0.67 s after the start"
        assert last_half_along < 200.0, f"last half {last_half_along:.0f} mm off along the walk after re-acquisition"
        assert last_half < 1000.0, f"last half {last_half:.0f} mm after re-acquisition"
    else:
        assert result["recovery"]["reacquisitions"] == 0 and (summary["reacquired"] == 0).all()
        assert second_quarter_along > 500.0, \
            f"without recovery the wrong start was corrected at once anyway ({second_quarter_along:.0f} mm along the walk)"


def test_automatic_start_without_empty_frames(tmp_path):
    """No start description and no background-only frames (issue 12 §1-2): the features node learns a
    robust background from the walk itself, the tracker finds the walking person within about a
    second of having a background and tracks from there, about as well as from a hand-written start."""
    import numpy as np
    import yaml

    from awalker_tools import evaluation

    from awalker_tools.bagio import SequenceReader, SequenceWriter
    from awalker_tracker.model.body import BodyDescription

    seq = tmp_path / "seq"
    assert main(["synth", "--out", str(seq), "--frames", "66", "--background-frames", "0", "--size", *SIZE,
                 "--seed", str(SYNTH_SEED), "--cameras", "1"]) == 0
    # the frames alone: no start or body description anywhere (a user's own video)
    bare = tmp_path / "bare" / "walk.bag"
    bare.parent.mkdir()
    with SequenceReader(seq / "synth.bag") as reader, SequenceWriter(bare, reader.cameras, compressed=True,
                                                                    image_format="png") as writer:
        for stamp, images in reader.frames():
            writer.write_frame(int(stamp), images)
    out = tmp_path / "run"
    assert main(["track", str(bare), "--out", str(out), "--particles", str(PARTICLES),
                 "--seed", str(TRACK_SEED), "--no-overlay"]) == 0
    assert main(["eval", str(out), "--truth", str(seq / "ground_truth.csv")]) == 0
    run = yaml.safe_load((out / "run.yaml").read_text())
    assert "robust fit" in run["features"]["cam0"]["background"]
    assert run["start_source"].startswith("found automatically")
    # one camera and no stance leg: the gait says that left and right may be swapped, and so does the report
    from awalker_tracker.inference.gait import SIDES_NOTE
    assert json.loads((out / "gait.json").read_text())["sides_note"] == SIDES_NOTE
    assert main(["report", str(out)]) == 0 and "Left and right" in (out / "report.html").read_text()
    # and how it started: the automatic start, the scaled body's fitted legs, the stance leg weighed
    page = (out / "report.html").read_text()
    assert "found automatically" in page and "leg length fitted" in page and "stance leg at the start" in page
    # the automatic start's backlog of posteriors reaches the pose publisher whole, in both passes
    for info in (run, yaml.safe_load((out / "first_pass" / "run.yaml").read_text())):
        assert info["recorded"]["/awalker/joint_states"] == info["recorded"]["/awalker/posterior"] == info["posteriors"]
    # issue 12 §3: with no body description, a first pass with the body scaled to the silhouette's height,
    # then its leg length fitted to that pass's images, and the run again with it (`awalker track`'s default)
    first = yaml.safe_load((out / "first_pass" / "run.yaml").read_text())
    assert first["body_source"].startswith("scaled to the person's height")
    assert str(out / "first_pass" / "body_fitted.yaml") in run["body_source"]
    from awalker_tools.fit_body import HEIGHT_SCALED_FACTORS
    assert min(abs(run["body_fit"]["leg_factor"] - f) for f in HEIGHT_SCALED_FACTORS) < 1e-9
    # measured (tracker seed 0, 2026-11-26): thigh and shank 0.413 m scaled to the height, 0.401 fitted
    # (leg factor 0.97), true 0.41
    body, true_body = BodyDescription.from_yaml(out / "body.yaml"), BodyDescription.from_yaml(seq / "body.yaml")
    scaled = BodyDescription.from_yaml(out / "first_pass" / "body.yaml")
    assert scaled.leg_length == pytest.approx(true_body.leg_length, rel=0.1)
    assert body.leg_length == pytest.approx(true_body.leg_length, rel=0.1)
    found = yaml.safe_load((out / "start.yaml").read_text())["start"]
    # measured (synthesis seed 1, tracker seed 0): background from frames 0-19, walk found at frame 34, the
    # track started at frame 26
    assert found["frame"] <= 20 + 30
    # the start named no stance leg: the first pass weighed both, and the run stood on the one it chose
    assert found["stance_leg"] == run["body_fit"]["stance_leg"] and "fitted to the first pass's images" in \
        run["start_source"]
    assert yaml.safe_load((out / "first_pass" / "start.yaml").read_text())["start"]["stance_leg"] == "unknown"
    truth = evaluation.read_poses_csv(seq / "ground_truth.csv")
    row = int(np.flatnonzero(truth.frames == found["frame"])[0])
    pelvis = truth.markers[row, truth.marker_names.index("pelvis"), :2]
    assert np.linalg.norm(np.array(found["position"]) - pelvis) < 0.3
    heading = yaml.safe_load((seq / "start.yaml").read_text())["start"]["heading"]
    assert abs(np.degrees(np.angle(np.exp(1j * (found["heading"] - heading))))) < 20.0
    result = json.loads((out / "eval.json").read_text())
    # One camera after an automatic start: the depth is as good as the start's (feet rows in 4-pixel steps).
    # Absolute median over tracker seeds 0-4: 224-459 mm (swing knee rest 2.5 psi_hip; with the paper's
    # 5: 78-289; 212-347 with the median background and the start fitted over 0.7 s; 71-373 before the
    # background explained the shadow's penumbra). At seed 1 the particles' best start is 0.5 m off
    # in depth for the first 7 frames and comes within 0.37 m by the end. Tracker seeds 0-9 (2026-11-26):
    # 208-545 mm, median 242 (the bound before, 500, held for seeds 0-4 only). A track lost or walking off
    # from a wrong start: its pelvis stays or ends more than 0.5 m away (the last check). With the step width
    # (d62eded) seeds 0-7 and 9 pass and seed 8 fails: the track starts ~0.6 m off in depth and stays there
    # (599 mm, off the person on 38 of 40 frames; the fitted legs are the scaled ones, x1.00); not fixed.
    assert result["absolute_mm"]["median"] < 650.0
    assert result["walk"]["fallen_frames"] == 0 and not result["walk"]["end"]["off_person"]
    estimate = evaluation.read_poses_csv(out / "poses.csv")
    ground_error = np.linalg.norm(pelvis_offsets(estimate, truth)[:, :2], axis=1)
    assert np.all(ground_error[15:] < 0.5), "the pelvis is more than 0.5 m off the person after 0.5 s"


DRESSED_UTURN = ["--from-mocap", str(MOCAP / "07.asf"), str(MOCAP / "07_01.amc"), "--person", "dressed",
                 "--variant", "u-turn", "--frames", "132", "--cameras", "2", "--user-start", "--tape-measure"]


@pytest.fixture(scope="module")
def dressed_uturn(tmp_path_factory):
    """A real walk (CMU 07_01) turned round within 2 s, drawn by the dressed renderer (arms, clothes, shadow:
    not the tracker's body), two cameras, a start and body as a user would give them."""
    seq = tmp_path_factory.mktemp("dressed_uturn")
    assert main(["synth", "--out", str(seq), "--background-frames", str(BACKGROUND), "--size", *SIZE,
                 "--seed", str(SYNTH_SEED), *DRESSED_UTURN]) == 0
    return seq


@pytest.mark.parametrize("images", [True, False])
def test_a_real_walk_turning_round_is_followed(dressed_uturn, tmp_path, images: bool):
    """Issue 10 §6: with the images the track follows the person round the turn and ends on them; with the
    likelihood and recovery off (dead reckoning from the start description) it ends far off the person."""
    out = tmp_path / "run"
    extra = [] if images else ["--likelihood-scale", "0", "--no-recovery"]
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
        assert main(["track", str(dressed_uturn / "synth.bag"), "--out", str(out), "--particles", str(PARTICLES),
                     "--seed", str(TRACK_SEED), "--no-overlay", *extra]) == 0
    assert main(["eval", str(out)]) == 0
    result = json.loads((out / "eval.json").read_text())
    absolute, end = result["absolute_mm"]["median"], result["walk"]["end"]
    # measured (500 particles, synthesis seed 1): tracker seeds 0-2 absolute median 147-238 mm, last frame
    # 0.13-0.18 m off over the ground, heading 12-19 deg off (1-2 re-acquisitions); dead reckoning (images
    # unused, --likelihood-scale 0; seeds 0-2) 520/1667/755 mm, 5.1/2.1/3.7 m and 164/76/45 deg off at the end
    # (the prior's own turns set its heading; a scale of 1e-9 still let the images pick the MAP lineage). With the
    # pelvis ceilings (two cameras' default since 2026-11-29) dead reckoning ends 0.93-6.09 m off over tracker
    # seeds 0-9 (0.93 at seed 0; 3.05-6.3 before, the random numbers drawn otherwise), so 0.8 m is asked.
    if images:
        assert absolute < 450.0, f"absolute median {absolute:.0f} mm"
        assert end["pelvis_ground_error_m"] < 0.5 and not end["fallen"], end
        assert end["heading_error_deg"] < 45.0, end
    else:
        assert end["off_person"] and end["pelvis_ground_error_m"] > 0.8, (absolute, end)


DRESSED_STOP = ["--from-mocap", str(MOCAP / "07.asf"), str(MOCAP / "07_01.amc"), "--person", "dressed",
                "--variant", "stop", "--frames", "135", "--cameras", "2", "--user-start", "--tape-measure"]


@pytest.fixture(scope="module")
def dressed_stop(tmp_path_factory):
    """A real walk (CMU 07_01) in which the person stands still from 1.6 s to 3.1 s, then walks on;
    dressed renderer, two cameras, a start and body as a user would give them."""
    seq = tmp_path_factory.mktemp("dressed_stop")
    assert main(["synth", "--out", str(seq), "--background-frames", str(BACKGROUND), "--size", *SIZE,
                 "--seed", str(SYNTH_SEED), *DRESSED_STOP]) == 0
    return seq


@pytest.mark.parametrize("recovery", [True, False])
def test_a_person_who_stops_is_held_where_they_stand(dressed_stop, tmp_path, recovery: bool):
    """Issue 12 §6: the walker cannot stand still; with recovery the tracker notices the stop from the
    images, holds the body where it stands (summary.csv person_still) and walks on with the person; without,
    the walker walks on past the standing person."""
    import numpy as np

    from awalker_tools import evaluation

    out = tmp_path / "run"
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
        assert main(["track", str(dressed_stop / "synth.bag"), "--out", str(out), "--particles", str(PARTICLES),
                     "--seed", str(TRACK_SEED), "--no-overlay", *([] if recovery else ["--no-recovery"])]) == 0
    assert main(["eval", str(out)]) == 0
    result = json.loads((out / "eval.json").read_text())
    summary = evaluation.read_summary_csv(out / "summary.csv")
    seconds = (summary["frame"] - BACKGROUND) / 30.0            # since the person appeared
    still = summary["person_still"] > 0
    per_frame = result["per_frame"]
    error = dict(zip(per_frame["frame"], per_frame["absolute_mm"]))
    late_stop = [error[f] for f, s in zip(summary["frame"], seconds) if 2.25 <= s < 3.0 and f in error]
    if not recovery:
        assert not still.any()
        assert np.median(late_stop) > 500.0, np.median(late_stop)      # measured: 645-909 mm
        return
    # measured (500 particles, synthesis seed 1, tracker seeds 0-2; the person stands still 1.6-3.1 s): held
    # 1.83-3.17 s (41 frames), 187-285 mm absolute error in the stop's second half (645-909 without
    # recovery), last frame 0.09-0.22 m off (2.1-3.5 m without)
    assert still[(seconds >= 1.9) & (seconds < 3.0)].all()           # held through the stop
    assert not still[(seconds < 1.5) | (seconds >= 3.3)].any()       # and only then
    assert result["recovery"]["still_frames"] == int(still.sum())
    # the stop's second half, tracker seeds 0-9 (2026-11-27): 286/207/238/370/219/199/246/278/217/280 mm with
    # the soles drawn on the floor (before: 210/291/246/269/245/193/198/236/238/269; the same median, 241-242,
    # one seed further out); the bound 15 % above the worst, as for the others (README, the seed spread)
    assert np.median(late_stop) < 425.0, np.median(late_stop)
    end = result["walk"]["end"]
    assert end["pelvis_ground_error_m"] < 0.5 and not end["fallen"], end


@pytest.fixture(scope="module")
def dressed_two_people(tmp_path_factory):
    """CMU 07_01 walked by two people in different clothes, the second the other way 1.2 m further back
    (they cross), two cameras; start and body of the first as a user would give them."""
    seq = tmp_path_factory.mktemp("dressed_two_people")
    assert main(["synth", "--out", str(seq), "--background-frames", str(BACKGROUND), "--size", *SIZE,
                 "--seed", str(SYNTH_SEED), "--from-mocap", str(MOCAP / "07.asf"), str(MOCAP / "07_01.amc"),
                 "--person", "dressed", "--second-person", "--frames", "120", "--cameras", "2", "--user-start",
                 "--tape-measure"]) == 0
    return seq


def test_two_people_in_view_do_not_mix(dressed_two_people, tmp_path):
    """Issue 12 §2/§6: each camera's detection is the blob nearest to the person followed, so a second
    person does not capture a hand-started track (an automatic start follows the first person it sees:
    test_the_automatic_start_follows_one_of_two_people)."""
    import numpy as np

    from awalker_tools import evaluation

    seq = dressed_two_people
    out = tmp_path / "run"
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
        assert main(["track", str(seq / "synth.bag"), "--out", str(out), "--particles", str(PARTICLES),
                     "--seed", str(TRACK_SEED), "--no-overlay"]) == 0
    assert main(["eval", str(out)]) == 0
    result = json.loads((out / "eval.json").read_text())
    summary = evaluation.read_summary_csv(out / "summary.csv")
    # measured (500 particles, synthesis seed 1, tracker seeds 0-4): 89-293 mm absolute median (seeds 1-4:
    # 89-141), off the person on 0-6 of 120 frames, the last 10 frames' pelvis 0.07-0.19 m off (seed 0: 0.5,
    # its track slid along the walk in the last half second); before the background explained the
    # shadow's penumbra (seeds 0-2): 178-206 mm, off on 0-2 frames, last frame 0.06-0.18 m off. Before
    # detections were gated on the track (synthesis seed 0): 251 mm, off the person on 37 of 120 frames,
    # 19 frames wrongly held as standing (the two cameras' largest blobs were different people).
    walk = result["walk"]
    offsets = pelvis_offsets(evaluation.read_poses_csv(out / "poses.csv"),
                             evaluation.read_poses_csv(seq / "ground_truth.csv"))
    off = np.linalg.norm(offsets[:, :2], axis=1)
    assert np.median(off[-10:]) < 0.6 and not walk["end"]["fallen"], walk["end"]
    assert not summary["person_still"].any()
    assert walk["off_person_frames"] <= 10 and result["absolute_mm"]["median"] < 350.0


def test_the_automatic_start_follows_one_of_two_people(tmp_path):
    """Issue 12 §2/§6: two people in view, no start and no empty frames. The start finder follows the
    first person it sees (each camera's blob nearest to where they would be now; a detection 0.5 m off
    that is someone else or two people's blobs merged), so the start is one person's position, heading
    and speed. Measured (synthesis seed 1): the second person (the first one seen) at 0.09 m and 4
    degrees (120 frames: 0.13 m, 5 degrees); before the detections were gated, the largest blob of any
    camera alternated between them: 0.40 m and 28 degrees from the first person (120 frames: 1.0 and
    2.4 m from them); gated on the last sighting without the distance check: 0.29 m and 92 degrees.
    ``--follow-near`` (AutoStartConfig.follow_near) at where the first person enters chooses them instead."""
    import numpy as np
    import yaml

    from awalker_tools import evaluation
    from awalker_tools.bagio import SequenceReader
    from awalker_tracker.inference.autostart import AutoStartConfig, StartFinder
    from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor

    seq = tmp_path / "seq"
    assert main(["synth", "--out", str(seq), "--background-frames", "0", "--no-descriptions", "--size", *SIZE,
                 "--seed", str(SYNTH_SEED), "--from-mocap", str(MOCAP / "07.asf"), str(MOCAP / "07_01.amc"),
                 "--person", "dressed", "--second-person", "--frames", "70", "--cameras", "2"]) == 0
    with SequenceReader(seq / "synth.bag") as reader:
        cameras = reader.cameras
        extractors = [FeatureExtractor(FeatureConfig()) for _ in cameras]
        stamps, features = [], []
        for stamp, images in reader.frames():
            stamps.append(int(stamp))
            features.append([e.process(images[c.name]) for e, c in zip(extractors, cameras)])
    people = [evaluation.read_poses_csv(seq / csv) for csv in ("ground_truth.csv", "second_person.csv")]

    def misses(config: AutoStartConfig) -> list[tuple[float, float]]:
        """(distance m, heading error deg) of the start found from each person's pelvis track."""
        finder, found = StartFinder(cameras, 1 / 30, config), None
        for k, frame in enumerate(features):
            found = finder.push(k, frame)
            if found is not None:
                break
        found = found or finder.finish()
        assert found is not None, finder.status()
        out = []
        for person in people:
            row = int(np.flatnonzero(person.stamps_ns == stamps[found.frame])[0])
            pelvis = person.marker("pelvis")[:, :2]
            walk = pelvis[min(row + 10, len(pelvis) - 1)] - pelvis[max(row - 10, 0)]
            heading = abs(np.degrees(np.angle(np.exp(1j * (found.heading - np.arctan2(walk[1], walk[0]))))))
            out.append((float(np.linalg.norm(np.array(found.position) - pelvis[row])), heading))
        return out

    def on(miss: tuple[float, float]) -> bool:
        return miss[0] < 0.3 and miss[1] < 20.0

    first_seen = misses(AutoStartConfig())
    assert any(on(m) for m in first_seen), first_seen
    other = 0 if on(first_seen[1]) else 1                  # the person the default start did not follow
    enters = people[other].marker("pelvis")[0, :2]
    chosen = misses(AutoStartConfig(follow_near=(float(enters[0]), float(enters[1]))))
    assert on(chosen[other]) and not on(chosen[1 - other]), chosen
    # the same through the command line and the tracker node (a few particles: only the start is checked)
    out = tmp_path / "run"
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
        assert main(["track", str(seq / "synth.bag"), "--out", str(out), "--particles", "100", "--no-overlay",
                     "--follow-near", str(enters[0]), str(enters[1])]) == 0
    start = yaml.safe_load((out / "start.yaml").read_text())["start"]
    row = int(np.flatnonzero(people[other].stamps_ns == stamps[start["frame"]])[0])
    assert np.linalg.norm(np.array(start["position"]) - people[other].marker("pelvis")[row, :2]) < 0.3


@pytest.fixture(scope="module")
def dressed_side_walk(tmp_path_factory) -> Path:
    """A dressed CMU walk (07_01, 90 frames) seen by one side camera, with a user's start description and a
    tape-measured body: the `synth` output directory."""
    seq = tmp_path_factory.mktemp("dressed_side") / "seq"
    assert main(["synth", "--out", str(seq), "--background-frames", str(BACKGROUND), "--size", *SIZE,
                 "--seed", str(SYNTH_SEED), "--from-mocap", str(MOCAP / "07.asf"), str(MOCAP / "07_01.amc"),
                 "--person", "dressed", "--frames", "90", "--cameras", "1", "--user-start", "--tape-measure"]) == 0
    return seq


def along_camera_view(seq: Path, out: Path) -> "np.ndarray":
    """The tracked pelvis's offset from the truth along the first camera's horizontal view (m, + away from
    the camera), per frame."""
    import numpy as np

    from awalker_tools import evaluation
    from awalker_tracker.vision.camera import load_calibration

    camera = load_calibration(seq / "calibration.yaml")[0]
    view = camera.rotation[:, 2] * np.array([1.0, 1.0, 0.0])
    view /= np.linalg.norm(view)
    return pelvis_offsets(evaluation.read_poses_csv(out / "poses.csv"),
                          evaluation.read_poses_csv(seq / "ground_truth.csv")) @ view


def test_one_camera_does_not_drift_toward_the_camera(dressed_side_walk, tmp_path):
    """Issue 10 §4 (depth with one camera): a dressed CMU walk with a soft contact shadow seen from the side.
    The background explains the shadow (vision/densities.py), so the model's feet do not stand on it below
    the person's feet, nearer the camera: over the last second the pelvis is within 0.25 m of the truth
    along the camera's horizontal view. Measured (5000 particles, the default; synthesis seed 1): tracker
    seeds 0-2 -0.08/-0.12/-0.14 m (whole walk -0.03..-0.06); before the shadow's penumbra counted as
    background, -0.48 m at seed 0 (the benchmark's longer 07_01 straight walk, seeds 0-2: -0.41/+0.02/-0.43
    m). At 500 particles one camera's depth is dominated by
    the particles' spread (-0.25..+0.45 m over seeds 0-2 either way), hence the default here."""
    seq, out = dressed_side_walk, tmp_path / "run"
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
        assert main(["track", str(seq / "synth.bag"), "--out", str(out), "--particles", "5000",
                     "--seed", str(TRACK_SEED), "--no-overlay"]) == 0
    along_view = along_camera_view(seq, out)
    assert abs(along_view[-30:].mean()) < 0.25, f"last second {along_view[-30:].mean():+.2f} m along the view"


@pytest.mark.parametrize("recovery", [True, False])
def test_one_camera_reacquires_a_track_started_too_far_along_its_view(dressed_side_walk, tmp_path, recovery: bool):
    """Recovery with one camera (inference/recovery.py, ``lost_distance_one_camera_m``): started 1 m farther
    along the camera's horizontal view than the person (a wrong start description), the body still
    projects onto the person's image, so only where the blob's feet row puts the person tells that it is
    lost. With recovery the track is re-acquired within half a second and stays near the person in depth;
    without, it is still far off a second in."""
    import numpy as np
    import yaml

    from awalker_tools import evaluation
    from awalker_tracker.vision.camera import load_calibration

    seq = dressed_side_walk
    camera = load_calibration(seq / "calibration.yaml")[0]
    view = camera.rotation[:2, 2] / np.linalg.norm(camera.rotation[:2, 2])
    start = yaml.safe_load((seq / "start.yaml").read_text())
    start["start"]["position"] = [float(v) for v in np.asarray(start["start"]["position"], float) + 1.0 * view]
    (tmp_path / "start.yaml").write_text(yaml.safe_dump(start))
    out = tmp_path / "run"
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
        assert main(["track", str(seq / "synth.bag"), "--out", str(out), "--particles", "5000",
                     "--seed", str(TRACK_SEED), "--start", str(tmp_path / "start.yaml"), "--no-overlay",
                     *([] if recovery else ["--no-recovery"])]) == 0
    summary = evaluation.read_summary_csv(out / "summary.csv")
    along_view = along_camera_view(seq, out)
    one_second_in, last_half = float(np.median(along_view[20:40])), float(np.median(along_view[45:]))
    # measured (synthesis seed 1, tracker seeds 0-9, 2026-11-26; the pelvis's median offset along the view
    # 0.67-1.33 s after the start / over the last half, m): with recovery re-acquired 13 frames after the
    # start (seeds 3, 5, 8, 9 again at 28), +0.09/-0.05/+0.11/-0.15/+0.10/+0.18/+0.14/0.00/-0.13/-0.03 and
    # +0.19/-0.08/+0.02/-0.01/+0.23/+0.25/+0.22/+0.02/-0.23/-0.05; without +0.81/+0.86/+0.87/+0.95/+0.91/
    # +0.98/+1.33/+0.88/+1.02/+0.86 and +0.94/+0.96/+0.85/+0.98/+1.02/+1.14/+1.28/-0.06/+1.30/+1.09 (at seed 7
    # the images alone brought it back over the second half, so only the first second is compared)
    if recovery:
        fired = summary["frame"][summary["reacquired"] > 0] - summary["frame"][0]
        assert fired.size and fired[0] <= 20, f"re-acquired at {fired} frames after the start"
        assert abs(one_second_in) < 0.4 and abs(last_half) < 0.4, (one_second_in, last_half)
    else:
        assert (summary["reacquired"] == 0).all()
        assert yaml.safe_load((out / "run.yaml").read_text())["depth_band_m"] == 0.0   # no depth band either
        assert one_second_in > 0.5, one_second_in
