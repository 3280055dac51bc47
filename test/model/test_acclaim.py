"""CMU mocap loader: plausible body sizes and speed, resampling, errors."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import MOCAP_07

from awalker_tracker.errors import InputError
from awalker_tracker.inference.speed import walking_speed
from awalker_tracker.model.acclaim import MOCAP_RATE, body_from_markers, load_mocap, segments_from_markers
from awalker_tracker.model.body import MARKER_NAMES, BodyDescription

ASF, AMC = MOCAP_07 / "07.asf", MOCAP_07 / "07_01.amc"
M = {n: i for i, n in enumerate(MARKER_NAMES)}


@pytest.fixture(scope="module")
def trial():
    return load_mocap(ASF, AMC)


def test_lengths_heights_and_speed_are_human(trial):
    markers = trial.markers
    assert markers.shape == (316, 13, 3) and trial.rate == MOCAP_RATE
    stamps = np.round(np.arange(len(markers)) / trial.rate * 1e9).astype(np.int64)
    assert np.median(walking_speed(markers[:, M["pelvis"], :2], stamps)) == pytest.approx(1.37, abs=0.03)  # README
    hip_ankle = np.median(np.linalg.norm(markers[:, M["left_hip"]] - markers[:, M["left_ankle"]], axis=1))
    ankle_height = np.percentile(markers[:, M["left_ankle"], 2], 5)
    assert hip_ankle + ankle_height == pytest.approx(0.9, abs=0.06)  # leg ~0.9 m
    z = np.median(markers[..., 2], axis=0)
    assert z[M["head"]] > z[M["thorax"]] > z[M["pelvis"]] > z[M["left_knee"]] > z[M["left_ankle"]]
    assert 1.4 < z[M["head"]] < 1.75 and 0.75 < z[M["pelvis"]] < 1.0
    feet = markers[:, [M["left_heel"], M["right_heel"], M["left_toe"], M["right_toe"]], 2]
    assert -0.03 < feet.min() < 0.03  # the floor is at z ~ 0
    # Walking is horizontal and straight; left is on the left of the walking direction.
    travel = markers[-1, M["pelvis"]] - markers[0, M["pelvis"]]
    drift = markers[-100:, M["pelvis"], 2].mean() - markers[:100, M["pelvis"], 2].mean()
    assert abs(drift) < 0.06  # over a stride, height drifts only with the (slightly tilted) floor
    heading = travel[:2] / np.linalg.norm(travel[:2])
    left = markers[:, M["left_hip"], :2] - markers[:, M["right_hip"], :2]
    assert np.all(heading[0] * left[:, 1] - heading[1] * left[:, 0] > 0)


def test_resample_and_body_fit(trial):
    at30 = trial.resample(30.0)
    assert at30.markers.shape[0] == 79 and at30.rate == 30.0  # frames 0, 4, ..., 312 of 316
    assert np.allclose(at30.markers, trial.markers[::4][: at30.markers.shape[0]])
    at60 = trial.resample(60.0)
    assert np.allclose(at60.markers[1], trial.markers[2])
    body = body_from_markers(trial.markers)
    assert 0.35 < body.upper_leg_length < 0.48 and 0.35 < body.lower_leg_length < 0.48
    assert body.leg_length == pytest.approx(0.9, abs=0.06)
    segments = segments_from_markers(body, at30.markers)
    assert segments.origin.shape == (at30.markers.shape[0], 8, 3)
    rot = segments.rotation
    assert np.allclose(rot @ np.swapaxes(rot, -1, -2), np.eye(3), atol=1e-9)
    thigh_axis = at30.markers[:, M["left_knee"]] - at30.markers[:, M["left_hip"]]
    thigh_axis /= np.linalg.norm(thigh_axis, axis=1, keepdims=True)
    assert np.allclose(rot[:, 2, :, 2], thigh_axis)
    assert isinstance(body, BodyDescription)


def test_measured_body_stands_as_tall_as_the_person(trial):
    """The ankle height and heel offset are measured, not the template's: with the floor levelled, the
    body's standing hip height (``leg_length``, the walker's L) is what the person's hips reach at
    mid-stance (their highest, the knee nearly straight) to 1.5 cm (0.8); the template's ankle stood it
    2.5 cm taller."""
    from awalker_tools.walk_variants import level_floor

    markers = level_floor(trial.markers, trial.rate)
    body = body_from_markers(markers)
    highest_hip = np.percentile(markers[:, [M["left_hip"], M["right_hip"]], 2], 99)
    assert 0.0 < body.leg_length - highest_hip < 0.015
    template_ankle = replace(body, ankle_height=BodyDescription.default().ankle_height)
    assert template_ankle.leg_length - highest_hip > 0.02
    assert 0.03 < body.ankle_height < 0.06 and 0.04 < body.heel_offset < 0.06


def test_bad_files_are_input_errors(tmp_path):
    with pytest.raises(InputError, match="cannot read ASF"):
        load_mocap(tmp_path / "none.asf", AMC)
    bad_asf = tmp_path / "bad.asf"
    bad_asf.write_text(":units\n  length 0.45\n:bonedata\n  begin\n  name lfemur\n  end\n")
    with pytest.raises(InputError, match="malformed ASF skeleton"):
        load_mocap(bad_asf, AMC)
    no_legs = tmp_path / "no_legs.asf"
    no_legs.write_text(":root\n  order TX TY TZ RX RY RZ\n:bonedata\n  begin\n  name lfemur\n  direction 0 -1 0\n"
                       "  length 7\n  axis 0 0 0 XYZ\n  end\n:hierarchy\n  begin\n  root lfemur\n  end\n")
    with pytest.raises(InputError, match="not a CMU-style ASF"):
        load_mocap(no_legs, AMC)
    bad_amc = tmp_path / "bad.amc"
    bad_amc.write_text(":FULLY-SPECIFIED\n1\nroot 1 2 3 oops 5 6\n")
    with pytest.raises(InputError, match="malformed AMC"):
        load_mocap(ASF, bad_amc)
    empty = tmp_path / "empty.amc"
    empty.write_text(":FULLY-SPECIFIED\n:DEGREES\n")
    with pytest.raises(InputError, match="no frames"):
        load_mocap(ASF, empty)
