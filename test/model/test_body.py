"""Body description: sizes, parts, YAML round trip and errors."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from awalker_tracker.errors import InputError
from awalker_tracker.model.body import (
    MARKER_NAMES, PART_CLASSES, PART_NAMES, SEEN_HEIGHT_LEG_FRACTION, SKELETON_EDGES, BodyDescription)
from awalker_tracker.model.walker import WalkerParams


def test_default_body_is_an_adult_with_the_walkers_leg():
    body = BodyDescription.default()
    assert 1.65 < body.height < 1.85
    assert body.leg_length == pytest.approx(WalkerParams().leg_length, abs=0.005)
    assert body.walker_params().leg_length == pytest.approx(body.leg_length)
    # The rocker sole passes through both ends of the flat sole line.
    half = body.foot_length / 2
    assert body.sole_radius - np.sqrt(body.sole_radius**2 - half**2) == pytest.approx(body.sole_sag)
    assert len(MARKER_NAMES) == 13 and MARKER_NAMES[0] == "pelvis" and MARKER_NAMES[-1] == "right_toe"


def test_parts_follow_part_names_and_classes():
    body = BodyDescription.default()
    parts = body.parts
    assert tuple(p.name for p in parts) == PART_NAMES
    assert {p.part_class for p in parts} == set(PART_CLASSES)
    legs = {p.name: p for p in parts}
    assert legs["left_upper_leg"].length == body.upper_leg_length
    assert np.allclose(legs["right_foot"].radii_end, body.foot_radii_toe)
    assert all(p.radii_start.shape == (2,) and p.max_radius > 0 for p in parts)


def test_yaml_round_trip_and_partial_yaml(tmp_path):
    body = BodyDescription(upper_leg_length=0.45, torso_radii_top=(0.12, 0.2))
    path = tmp_path / "body.yaml"
    path.write_text(body.to_yaml_text())
    assert BodyDescription.from_yaml(path) == body
    partial = BodyDescription.from_yaml_text("body:\n  head_length: 0.3\n")
    assert partial.head_length == 0.3 and partial.upper_leg_length == BodyDescription().upper_leg_length


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("body: [1, 2", "not valid YAML"),
        ("cameras: []", "top-level 'body:'"),
        ("body:\n  thigh: 0.4\n", "unknown body field(s) thigh"),
        ("body:\n  head_length: tall\n", "body.head_length must be a number"),
        ("body:\n  foot_radii_toe: [0.02]\n", "body.foot_radii_toe must be a list of two numbers"),
        ("body:\n  torso_length: -0.5\n", "torso_length must be finite and > 0"),
        ("body:\n  heel_offset: 0.3\n", "heel_offset must be smaller than foot_length"),
    ],
)
def test_bad_yaml_names_the_file_and_the_problem(tmp_path, text, message):
    path = tmp_path / "bad_body.yaml"
    path.write_text(text)
    with pytest.raises(InputError) as err:
        BodyDescription.from_yaml(path)
    assert str(path) in str(err.value) and message in str(err.value)


def test_missing_file_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="cannot read body description"):
        BodyDescription.from_yaml(tmp_path / "nope.yaml")


def test_the_skeleton_joins_every_marker_once_per_edge():
    assert all(a in MARKER_NAMES and b in MARKER_NAMES and a != b for a, b in SKELETON_EDGES)
    assert len({frozenset(e) for e in SKELETON_EDGES}) == len(SKELETON_EDGES) == 14
    reached, frontier = {"pelvis"}, ["pelvis"]           # one connected figure
    while frontier:
        here = frontier.pop()
        for a, b in SKELETON_EDGES:
            for near, far in ((a, b), (b, a)):
                if near == here and far not in reached:
                    reached.add(far)
                    frontier.append(far)
    assert reached == set(MARKER_NAMES)


def test_legs_scaled_changes_thigh_and_shank_only():
    body = BodyDescription.default()
    longer = body.legs_scaled(1.05)
    assert longer.upper_leg_length == pytest.approx(1.05 * body.upper_leg_length)
    assert longer.lower_leg_length == pytest.approx(1.05 * body.lower_leg_length)
    assert longer.leg_length - body.leg_length == pytest.approx(0.05 * (body.upper_leg_length + body.lower_leg_length))
    assert (longer.torso_length, longer.ankle_height, longer.hip_width) == (body.torso_length, body.ankle_height,
                                                                            body.hip_width)


def test_legs_scaled_keeping_the_height_takes_it_from_torso_and_head():
    body = BodyDescription.default()
    longer = body.legs_scaled(1.06, keep_height=True)
    assert longer.height == pytest.approx(body.height)
    assert longer.leg_length == pytest.approx(body.legs_scaled(1.06).leg_length)
    lost = body.torso_length + body.head_length - (longer.torso_length + longer.head_length)
    assert lost == pytest.approx(longer.leg_length - body.leg_length)
    assert longer.torso_length / longer.head_length == pytest.approx(body.torso_length / body.head_length)
    assert (longer.ankle_height, longer.hip_width, longer.foot_length) == (body.ankle_height, body.hip_width,
                                                                           body.foot_length)
    assert body.legs_scaled(0.94, keep_height=True).torso_length > body.torso_length
    short_trunk = replace(body, torso_length=0.30, head_length=0.20)
    with pytest.raises(ValueError, match="torso and head"):      # more than half of torso and head gone to the legs
        short_trunk.legs_scaled(1.4, keep_height=True)


def test_a_body_from_the_seen_height_has_that_height_and_with_two_cameras_the_walking_leg_fraction():
    for height in (1.45, 1.70, 1.95):
        scaled = BodyDescription.default().scaled_to_height(height)
        # one camera: the default's proportions (awalker track fits the legs next)
        assert BodyDescription.from_seen_height(height, 1) == scaled
        body = BodyDescription.from_seen_height(height, 2)
        assert body == BodyDescription.from_seen_height(height, 3)
        assert body.height == pytest.approx(height)
        assert body.leg_length == pytest.approx(SEEN_HEIGHT_LEG_FRACTION * height)
        # the legs longer than the default's proportion, the rest of the shape as scaled
        assert body.leg_length > scaled.leg_length + 0.02
        assert body.torso_length / body.head_length == pytest.approx(scaled.torso_length / scaled.head_length)
        assert (body.ankle_height, body.hip_width, body.foot_length) == (scaled.ankle_height, scaled.hip_width,
                                                                         scaled.foot_length)
        assert body.upper_leg_length / body.lower_leg_length == pytest.approx(1.0)
    with pytest.raises(ValueError, match="height must lie"):
        BodyDescription.from_seen_height(0.5, 2)
