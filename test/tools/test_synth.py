"""awalker synth: complete, deterministic bags whose ground truth lines up with the pixels."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import yaml
from conftest import MOCAP_07

from awalker_tools import cli
from awalker_tools.bagio import SequenceReader, occlusion_mask_topic
from awalker_tools.overlay import draw_body, save_overlay_png
from awalker_tracker.model.body import MARKER_NAMES, BodyDescription
from awalker_tracker.vision.camera import load_calibration

M = {n: i for i, n in enumerate(MARKER_NAMES)}
SMALL = ["--size", "200", "150", "--frames", "14", "--background-frames", "3"]


def synth(out, *extra: str) -> int:
    return cli.main(["synth", "--out", str(out), *SMALL, *extra])


def read(out):
    with SequenceReader(out / "synth.bag") as bag:
        cameras = bag.cameras
        frames = list(bag.frames())
        stamps, markers = bag.ground_truth()
        start = bag.text("/awalker/start_description")
        masks = [m for _, _, _, m in bag.messages([occlusion_mask_topic(cameras[0].name)])]
    return cameras, frames, stamps, markers, start, masks


def on_mask(camera, mask: np.ndarray, point: np.ndarray) -> bool:
    """Whether world ``point`` (3,) projects onto an occluded pixel (255) of ``mask`` (H, W)."""
    (u, v), _ = camera.project(point)
    u, v = int(round(u)), int(round(v))
    return bool(0 <= u < mask.shape[1] and 0 <= v < mask.shape[0] and mask[v, u] == 255)


def test_synth_is_complete_deterministic_and_lines_up(tmp_path):
    assert synth(tmp_path / "a", "--seed", "3", "--cameras", "2") == 0
    assert synth(tmp_path / "b", "--seed", "3", "--cameras", "2") == 0
    assert synth(tmp_path / "c", "--seed", "4", "--cameras", "2") == 0
    a, b, c = (tmp_path / k for k in "abc")
    assert (a / "ground_truth.csv").read_text() == (b / "ground_truth.csv").read_text()
    assert (a / "ground_truth.csv").read_text() != (c / "ground_truth.csv").read_text()
    cameras, frames, stamps, markers, start_text, _ = read(a)
    _, frames_b, *_ = read(b)
    assert all(np.array_equal(fa[1][k], fb[1][k]) for fa, fb in zip(frames, frames_b) for k in fa[1])
    assert [cam.name for cam in cameras] == ["cam0", "cam1"] and len(frames) == 17
    assert markers.shape == (14, 13, 3) and np.all(np.diff(stamps) > 0)
    assert list(stamps) == [s for s, _ in frames[3:]]  # ground truth from the first frame with the person
    # Side files agree with the bag.
    start = yaml.safe_load((a / "start.yaml").read_text())["start"]
    assert yaml.safe_load(start_text)["start"] == start and start["frame"] == 3
    assert np.allclose(start["position"], markers[0, M["pelvis"], :2], atol=1e-3)
    assert start["stance_leg"] in ("left", "right") and start["speed"] == 1.3
    calibration = load_calibration(a / "calibration.yaml")
    assert all(np.allclose(x.K, y.K) and np.allclose(x.position, y.position) for x, y in zip(calibration, cameras))
    assert BodyDescription.from_yaml(a / "body.yaml") == BodyDescription.default()
    rows = (a / "ground_truth.csv").read_text().strip().splitlines()
    assert rows[0] == "frame,stamp_ns,marker,x,y,z" and len(rows) == 1 + 14 * 13
    frame, stamp, name, *xyz = rows[1 + 5 * 13 + M["left_knee"]].split(",")
    assert (int(frame), int(stamp), name) == (8, stamps[5], "left_knee")
    assert np.allclose([float(v) for v in xyz], markers[5, M["left_knee"]], atol=1e-6)
    # Ground truth lines up: points inside the body (mid torso, mid thighs) project onto pixels
    # that differ from the empty room much more than points 0.5 m beside the body do.
    empty = {k: v.astype(float) for k, v in frames[0][1].items()}
    on_body, beside = [], []
    for index in range(14):
        _, images = frames[3 + index]
        m = markers[index]
        inside = [0.5 * (m[M["pelvis"]] + m[M["thorax"]]), 0.5 * (m[M["left_hip"]] + m[M["left_knee"]]),
                  0.5 * (m[M["right_hip"]] + m[M["right_knee"]])]
        for cam in cameras:
            sideways = np.cross(cam.rotation[:, 2], [0.0, 0.0, 1.0])
            for point in inside:
                for offset, store in ((0.0, on_body), (0.5, beside)):
                    (u, v), _ = cam.project(point + offset * sideways)
                    u, v = int(round(u)), int(round(v))
                    store.append(np.abs(images[cam.name][v - 1 : v + 2, u - 1 : u + 2].astype(float)
                                        - empty[cam.name][v - 1 : v + 2, u - 1 : u + 2]).mean())
    assert np.median(on_body) > 3 * np.median(beside) and np.median(on_body) > 30
    # The body walks at about the requested speed.
    travel = np.linalg.norm(markers[-1, M["pelvis"], :2] - markers[0, M["pelvis"], :2]) / (13 / 30)
    assert travel == pytest.approx(1.3, rel=0.25)
    overlay = draw_body(frames[10][1]["cam0"], markers[7], cameras[0])
    assert np.count_nonzero(np.any(overlay != frames[10][1]["cam0"], axis=2)) > 50
    assert save_overlay_png(tmp_path / "overlay.png", frames[10][1]["cam0"], markers[7], cameras[0]).stat().st_size > 0
    assert (a / "overlay_cam0.png").stat().st_size > 0 and (a / "overlay_cam1.png").is_file()
    # Filled parts: the rendered body is blended in (more pixels change than for the skeleton alone).
    from awalker_tracker.model.acclaim import segments_from_markers
    body = BodyDescription.default()
    filled = draw_body(frames[10][1]["cam0"], markers[7], cameras[0], segments_from_markers(body, markers[7:8]), body)
    assert np.count_nonzero(np.any(filled != frames[10][1]["cam0"], axis=2)) > \
        np.count_nonzero(np.any(overlay != frames[10][1]["cam0"], axis=2))


def test_turn_and_occluder(tmp_path):
    assert synth(tmp_path, "--turn", "80", "--occluder", "--frames", "30", "--seed", "1") == 0
    cameras, frames, stamps, markers, _, masks = read(tmp_path)
    early = markers[6, M["pelvis"], :2] - markers[0, M["pelvis"], :2]
    late = markers[-1, M["pelvis"], :2] - markers[-7, M["pelvis"], :2]
    turned = np.degrees(np.arctan2(late[1], late[0]) - np.arctan2(early[1], early[0]))
    assert turned == pytest.approx(80, abs=15)
    assert len(masks) == len(frames)
    mask = np.frombuffer(bytes(masks[0].data), np.uint8).reshape(masks[0].height, masks[0].width)
    assert set(np.unique(mask)) == {0, 255}
    # Some frame has a knee or ankle behind the occluder, none has the head behind it.
    lower = ("left_ankle", "right_ankle", "left_knee", "right_knee")
    hidden_lower = any(on_mask(cameras[0], mask, markers[k, M[n]]) for k in range(len(markers)) for n in lower)
    hidden_head = any(on_mask(cameras[0], mask, markers[k, M["head"]]) for k in range(len(markers)))
    assert hidden_lower and not hidden_head


def test_occluder_hides_the_legs_for_a_stretch_only(tmp_path):
    """The box stands in front of half of the walk (synth.OCCLUDED_SHARE): both feet are hidden for a
    stretch and seen before and after it, so a tracker has the legs' phase going in (the box was once as
    wide as a 40-frame walk, which hid the legs throughout)."""
    assert synth(tmp_path, "--occluder", "--frames", "40", "--seed", "1") == 0
    cameras, frames, stamps, markers, _, masks = read(tmp_path)
    hidden = []
    for k, msg in enumerate(masks[-len(markers):]):
        mask = np.frombuffer(bytes(msg.data), np.uint8).reshape(msg.height, msg.width)
        hidden.append(all(on_mask(cameras[0], mask, markers[k, M[n]]) for n in ("left_ankle", "right_ankle")))
    hidden = np.array(hidden)
    assert not hidden[:5].any() and not hidden[-5:].any()
    assert 0.15 < hidden.mean() < 0.45


def test_from_mocap(tmp_path):
    assert synth(tmp_path, "--from-mocap", str(MOCAP_07 / "07.asf"), str(MOCAP_07 / "07_01.amc"),
                 "--rate", "60") == 0
    cameras, frames, stamps, markers, start_text, _ = read(tmp_path)
    assert np.allclose(np.diff(stamps), 1e9 / 60, atol=1)
    start = yaml.safe_load(start_text)["start"]
    assert start["speed"] == pytest.approx(1.37, abs=0.15) and abs(start["heading"]) < 0.2
    body = BodyDescription.from_yaml(tmp_path / "body.yaml")
    assert body.leg_length == pytest.approx(0.9, abs=0.06)
    # More frames than the walk holds: the walk is repeated from a matching frame, moving on
    assert cli.main(["synth", "--out", str(tmp_path / "long"), "--size", "80", "60",
                     "--frames", "200", "--background-frames", "0",
                     "--from-mocap", str(MOCAP_07 / "07.asf"), str(MOCAP_07 / "07_01.amc")]) == 0
    _, _, _, long, _, _ = read(tmp_path / "long")
    assert long.shape == (200, 13, 3)
    pelvis_speed = np.linalg.norm(np.diff(long[:, M["pelvis"], :2], axis=0), axis=1) * 30
    assert pelvis_speed.max() < 2.2 and pelvis_speed.min() > 0.8     # no jump where the walk repeats
    travel = long[-1, M["pelvis"], :2] - long[0, M["pelvis"], :2]
    assert np.linalg.norm(travel) / (199 / 30) == pytest.approx(1.37, abs=0.15)


@pytest.mark.parametrize(
    ("args", "message"),
    [(["--cameras", "5"], "--cameras must be 1..4"), (["--turn", "120"], "--turn must be within"),
     (["--occluder", "-0.5"], "--occluder SHARE must lie in 0-2"),
     (["--from-mocap", "missing.asf", "missing.amc"], "missing.asf"),
     (["--from-mocap", "a.asf", "b.amc", "--turn", "30"], "takes --variant"),
     (["--person", "dressed"], "need a motion capture walk"), (["--variant", "u-turn"], "need a motion capture walk"),
     (["--from-mocap", "a.asf", "b.amc", "--variant", "u-turn"], "needs --frames >= 126")],
)
def test_bad_options_are_one_line_errors(tmp_path, capsys, args, message):
    assert synth(tmp_path, *args) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_existing_bag_is_not_overwritten(tmp_path, capsys):
    assert synth(tmp_path, "--frames", "3") == 0
    before = {f: f.stat().st_mtime_ns for f in tmp_path.rglob("*") if f.is_file()}
    assert synth(tmp_path, "--frames", "3") == 2
    assert "expected a new or empty folder" in capsys.readouterr().err
    assert {f: f.stat().st_mtime_ns for f in tmp_path.rglob("*") if f.is_file()} == before     # nothing rewritten


MOCAP = ["--from-mocap", str(MOCAP_07 / "07.asf"), str(MOCAP_07 / "07_01.amc")]


def test_dressed_person_is_not_the_model_body(tmp_path):
    """`--person dressed` draws arms, clothes and a head the tracker's body lacks: more of the image
    differs from the empty room than the model body covers, and both legs wear the same colour."""
    from awalker_tracker.model.acclaim import segments_from_markers
    from awalker_tracker.vision.render import render

    assert synth(tmp_path / "model", *MOCAP, "--seed", "2") == 0
    assert synth(tmp_path / "dressed", *MOCAP, "--seed", "2", "--person", "dressed") == 0
    cameras, frames, _, markers, _, _ = read(tmp_path / "dressed")
    body = BodyDescription.from_yaml(tmp_path / "dressed" / "body.yaml")
    room = frames[0][1]["cam0"].astype(float)
    k = 8                                                              # a frame with the person
    image = frames[3 + k][1]["cam0"].astype(float)
    changed = np.abs(image - room).sum(axis=2) > 60
    model = render(body, segments_from_markers(body, markers[k][None]), cameras[0])
    inside = model.labels >= 0
    assert changed[~inside].sum() > 0.3 * inside.sum()                 # arms, shoulders, hair outside the model
    # the same trousers on both legs: mid-thigh pixels of the left and right leg have one colour
    uv, _ = cameras[0].project(0.5 * (markers[k, [M["left_hip"], M["right_hip"]]] + markers[k, [M["left_knee"], M["right_knee"]]]))
    left, right = (image[int(round(v)), int(round(u))] for u, v in uv)
    assert np.abs(left - right).max() < 40
    _, model_frames, *_ = read(tmp_path / "model")
    assert not np.array_equal(model_frames[3 + k][1]["cam0"], frames[3 + k][1]["cam0"])


def test_dressed_shoes_stand_on_the_floor_while_the_foot_lies_flat(tmp_path):
    """The dressed person's shoe soles reach the floor while their foot lies flat (the skeleton's heel-toe
    line runs ~3 cm over the sole: drawn along it, the person floated), and nothing is drawn under the
    floor while the foot rolls. Checked on the pixels: a side camera's rendered shoe pixels, put back in
    3D through their depth, reach down to the floor within 8 mm in flat-foot frames (3-4 cm before; a pixel is 6 mm
    there) and never below it, though the shoes' capsules reach 2-3 cm under it while a foot rolls."""
    from awalker_tools.person_render import Outfit, PersonRenderer, capsules
    from awalker_tools.synth import SynthConfig, make_cameras, walk_variants
    from awalker_tracker.model.acclaim import flat_foot_frames

    config = SynthConfig(tmp_path, frames=40, mocap=(MOCAP_07 / "07.asf", MOCAP_07 / "07_01.amc"),
                         person="dressed", width=960, height=720)
    motion = walk_variants(config, np.zeros(2), 0.0)
    camera = make_cameras(1, 960, 720, motion.markers[20, M["pelvis"], :2])[0]
    green_shoes = replace(Outfit.random(np.random.default_rng(0)), shoes=(0.0, 220.0, 0.0))   # nothing else is green
    renderer = PersonRenderer(camera, green_shoes, blur_sigma_px=0.0)
    flat = {side: flat_foot_frames(motion.markers, side) for side in ("left", "right")}
    lowest, flat_lowest, under = [], [], []
    for k in range(0, 40, 2):
        image, depth = renderer.render(motion.points[k], np.zeros((720, 960, 3), np.float32))
        under += [min(a[2], b[2]) - r for a, b, r, material in capsules(motion.points[k], renderer.outfit)
                  if material == "shoes"]
        person = np.isfinite(depth)
        points = camera.position + renderer.rays[person] * (depth[person] / renderer.depth_per_t[person])[:, None]
        lowest.append(float(points[:, 2].min()))
        shoe = image[person][:, 1] > 2.0 * (image[person][:, 0] + image[person][:, 2]) + 10.0
        for side in ("left", "right"):            # a flat foot's shoe: green pixels near its heel-toe midpoint
            middle = 0.5 * (motion.markers[k, M[f"{side}_heel"]] + motion.markers[k, M[f"{side}_toe"]])
            near = shoe & (np.linalg.norm(points[:, :2] - middle[:2], axis=1) < 0.15)
            if flat[side][k] and near.any():
                flat_lowest.append(float(points[near, 2].min()))
    assert min(lowest) >= -0.001
    assert len(flat_lowest) >= 3 and np.median(flat_lowest) < 0.008
    assert min(under) < -0.015


@pytest.mark.parametrize("carry", ["shoulder-bag", "backpack"])
def test_a_carried_bag_is_drawn_where_it_is_carried(tmp_path, carry):
    """`--carry`: the same sequence (the same random numbers) plus a bag the tracker's body lacks: the
    frames differ only around it, by enough pixels to matter, beside the right hip (a shoulder bag) or
    behind the torso (a backpack); the truth is the person's alone."""
    common = [*MOCAP, "--seed", "2", "--person", "dressed", "--image-format", "raw", "--size", "320", "240"]
    assert synth(tmp_path / "plain", *common) == 0
    assert synth(tmp_path / carry, *common, "--carry", carry) == 0
    cameras, plain, _, markers, _, _ = read(tmp_path / "plain")
    _, carrying, _, carrying_markers, _, _ = read(tmp_path / carry)
    np.testing.assert_array_equal(markers, carrying_markers)
    assert np.array_equal(plain[0][1]["cam0"], carrying[0][1]["cam0"])          # the empty room, noise and all
    k = 8
    image, other = (frames[3 + k][1]["cam0"].astype(int) for frames in (plain, carrying))
    rows, cols = np.nonzero(np.abs(image - other).sum(axis=2) > 30)
    assert len(rows) > 40
    centroid = np.array([cols.mean(), rows.mean()])
    walk = markers[k + 1, M["pelvis"]] - markers[k - 1, M["pelvis"]]
    walk[2] = 0.0
    walk /= np.linalg.norm(walk)
    if carry == "shoulder-bag":
        uv, _ = cameras[0].project(markers[k, [M["right_hip"], M["thorax"]]])
        hip, thorax = uv
        assert np.linalg.norm(centroid - hip) < 0.5 * np.linalg.norm(centroid - thorax)
    else:
        back = 0.5 * (markers[k, M["pelvis"]] + markers[k, M["thorax"]])
        uv, _ = cameras[0].project(np.array([back, back + 0.3 * walk]))
        ahead = uv[1] - uv[0]
        assert (centroid - uv[0]) @ ahead < 0                                    # behind the torso's middle
    assert synth(tmp_path / "model", "--carry", carry) == 2                      # the model body carries nothing


@pytest.mark.parametrize(("variant", "turn_deg", "speed_factor"),
                         [("u-turn", 180.0, 1.0), ("veer-left", 35.0, 1.0), ("veer-right", -35.0, 1.0),
                          ("fast", 0.0, 1.2), ("slow", 0.0, 0.8)])
def test_walk_variants_turn_and_change_speed_without_foot_skate(tmp_path, variant, turn_deg, speed_factor):
    from awalker_tools import walk_variants
    from awalker_tracker.inference.gait_events import stance_from_heels

    frames = 130 if turn_deg else 60
    assert cli.main(["synth", "--out", str(tmp_path / variant), "--size", "80", "60", "--frames", str(frames),
                     "--background-frames", "0", *MOCAP, "--variant", variant]) == 0
    assert cli.main(["synth", "--out", str(tmp_path / "straight"), "--size", "80", "60", "--frames", str(frames),
                     "--background-frames", "0", *MOCAP]) == 0
    _, _, _, walk, _, _ = read(tmp_path / variant)
    _, _, _, straight, _, _ = read(tmp_path / "straight")
    facing = np.unwrap(walk_variants.facing(walk))
    facing_straight = np.unwrap(walk_variants.facing(straight))
    turned = np.degrees((facing[-10:].mean() - facing[:10].mean()) - (facing_straight[-10:].mean() - facing_straight[:10].mean()))
    assert turned == pytest.approx(turn_deg, abs=12)
    if turn_deg:     # within the variant's 2 (u-turn) or 2.5 (veer) s, then straight again
        late = np.degrees(facing[-25:] - facing_straight[-25:])
        assert np.ptp(late) < 15
    speed = np.linalg.norm(np.diff(walk[:30, M["pelvis"], :2], axis=0), axis=1).mean()
    speed_straight = np.linalg.norm(np.diff(straight[:30, M["pelvis"], :2], axis=0), axis=1).mean()
    assert speed / speed_straight == pytest.approx(speed_factor, rel=0.05)
    # turning pivots on the stance foot's contact (its lower end, heel or toe): that point does not slide
    # more than in the recorded walk
    def slide(points):
        stance, _ = stance_from_heels(points, np.arange(len(points)) / 30.0)
        moves = []
        for f in range(1, len(points)):
            if stance[f] != stance[f - 1]:
                continue
            ends = [M["left_heel"], M["left_toe"]] if stance[f] == 0 else [M["right_heel"], M["right_toe"]]
            contact = ends[int(np.argmin(points[f, ends, 2]))]
            moves.append(np.linalg.norm(points[f, contact, :2] - points[f - 1, contact, :2]))
        return np.median(moves)
    assert slide(walk) < slide(straight) + 0.003


def test_user_start_and_tape_measure_differ_from_the_truth_a_little(tmp_path):
    assert synth(tmp_path / "exact", *MOCAP) == 0
    assert synth(tmp_path / "user", *MOCAP, "--user-start", "--tape-measure") == 0
    exact = yaml.safe_load((tmp_path / "exact" / "start.yaml").read_text())["start"]
    user = yaml.safe_load((tmp_path / "user" / "start.yaml").read_text())["start"]
    assert "step_length" in exact and "step_length" not in user
    assert 0 < np.linalg.norm(np.subtract(user["position"], exact["position"])) <= 0.051
    assert 0 < abs(user["heading"] - exact["heading"]) <= np.radians(5) + 1e-3
    assert abs(user["speed"] / exact["speed"] - 1) <= 0.11
    body_exact = BodyDescription.from_yaml(tmp_path / "exact" / "body.yaml")
    body_user = BodyDescription.from_yaml(tmp_path / "user" / "body.yaml")
    ratio = body_user.upper_leg_length / body_exact.upper_leg_length
    assert ratio != 1.0 and abs(ratio - 1) <= 0.061
    # the person's own sizes are written beside the truth, tape or not: what body.yaml holds without the tape
    own = BodyDescription.from_yaml(tmp_path / "user" / "ground_truth_body.yaml")
    assert own.to_yaml_text() == body_exact.to_yaml_text() != body_user.to_yaml_text()
    assert (tmp_path / "exact" / "ground_truth_body.yaml").read_text() == body_exact.to_yaml_text()


def test_no_descriptions_is_a_users_own_video(tmp_path):
    """--no-descriptions: the same frames and truth, but no start or body description in the bag or beside it."""
    assert synth(tmp_path / "with", *MOCAP) == 0
    assert synth(tmp_path / "bare", *MOCAP, "--no-descriptions") == 0
    assert not (tmp_path / "bare" / "start.yaml").exists() and not (tmp_path / "bare" / "body.yaml").exists()
    _, frames, stamps, markers, start, _ = read(tmp_path / "bare")
    _, frames_with, _, markers_with, start_with, _ = read(tmp_path / "with")
    with SequenceReader(tmp_path / "bare" / "synth.bag") as bag:
        assert bag.text("/awalker/body_description") is None
    assert start is None and start_with is not None
    assert np.array_equal(markers, markers_with)
    assert all(np.array_equal(a[1]["cam0"], b[1]["cam0"]) for a, b in zip(frames, frames_with))


def test_stop_variant_stands_still_with_both_feet_down_then_walks_on(tmp_path):
    from awalker_tools.synth import PAUSES

    rate = 30.0
    assert cli.main(["synth", "--out", str(tmp_path / "stop"), "--size", "80", "60", "--frames", "140",
                     "--background-frames", "0", *MOCAP, "--variant", "stop"]) == 0
    _, _, _, walk, _, _ = read(tmp_path / "stop")
    speed = np.linalg.norm(np.diff(walk[:, M["pelvis"], :2], axis=0), axis=1) * rate
    still = np.flatnonzero(speed < 1e-6)
    begin, duration = PAUSES["stop"]
    assert still.size == int(round(duration * rate)) and np.all(np.diff(still) == 1)     # one stop, as long as asked
    assert begin * rate <= still[0] <= (begin + 0.5) * rate
    feet = walk[still[0], [M["left_heel"], M["left_toe"], M["right_heel"], M["right_toe"]], 2]
    assert feet.reshape(2, 2).min(axis=1).max() < 0.05                 # both feet on the floor
    assert speed[: still[0]].mean() > 1.0 and speed[still[-1] + 2:].mean() > 1.0     # walking before and after


def test_start_heading_is_the_walking_direction_over_strides(tmp_path):
    """The start description's heading is where the person walks, not where the pelvis sways in the first
    few frames: within 1.5 degrees of the pelvis's direction over the first two seconds (the user's
    start may then add up to 5 degrees, as the issue asks; a 0.3 s window was 3-6 degrees off on CMU 07)."""
    for walk in ("07_01", "07_02"):
        out = tmp_path / walk
        assert cli.main(["synth", "--out", str(out), "--size", "80", "60", "--frames", "64", "--background-frames",
                         "0", "--from-mocap", str(MOCAP_07 / "07.asf"), str(MOCAP_07 / f"{walk}.amc")]) == 0
        _, _, _, markers, _, _ = read(out)
        start = yaml.safe_load((out / "start.yaml").read_text())["start"]
        path = markers[60, M["pelvis"], :2] - markers[0, M["pelvis"], :2]
        walking = np.arctan2(path[1], path[0])
        assert abs(np.degrees(start["heading"] - walking)) < 1.5, walk
