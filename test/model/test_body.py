"""Body description: sizes, parts, YAML round trip and errors."""
from __future__ import annotations

import numpy as np
import pytest

from awalker_tracker.errors import InputError
from awalker_tracker.model.body import MARKER_NAMES, PART_CLASSES, PART_NAMES, SKELETON_EDGES, BodyDescription
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
