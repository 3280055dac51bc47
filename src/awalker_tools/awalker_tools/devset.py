"""The broad development set: real walks of eight CMU subjects, each run drawn as a user would record it.

A *trial* is a stretch of one CMU motion-capture file (``test/data/mocap``, its README): straight walks,
slow walks, starts from standing, a curved U-turn, a turn on the spot, slow turns with pauses, a small
subject; two of subject 7's walks also turned round or veering by ``walk_variants.bend`` (``BENT``). The
subjects are split once, before any measurement, into a tuning set (what the tracker may be tuned on)
and a reporting set (what accuracy figures are reported on; never tuned on): ``TUNING_SUBJECTS``,
``REPORTING_SUBJECTS``. ``QUICK`` is a small tuning subset for frequent runs.

A *recording* is a trial drawn from a seed (``Recording.draw``): everything a user's own recording
varies, drawn per run so that no constant is tuned on one draw:

- the person's shape: the whole skeleton scaled by 0.92-1.08 (with the subjects' own sizes: adults of
  about 1.45-1.95 m) and the upper body about the pelvis by 0.93-1.07 (trunk to leg proportions), limb
  widths and clothes from ``person_render.Outfit.draw`` (trousers, shorts or a skirt; light, mid or dark;
  plain or patterned; a body build from slim to heavy);
- the cameras (``draw_camera``): 0.8-3 m high, 3-10 m from the middle of the walk, seen from any side
  between nearly frontal or from nearly behind (15 degrees off the line the walk starts along) and side-on
  (``off_the_walking_line``), a horizontal field of view of 50-75
  degrees widened until the whole walk is in view, slight lens distortion; two cameras at least 45 degrees
  apart around the walk; 30 or 60 Hz and 640x480 or 1280x720 for the recording;
- the light: exposure 0.65-1.15, a colour tint of +-8 % per channel, a slow change of up to 30 %, sensor
  noise of 1-6 grey levels, lens blur of 0.4-1.2 pixels; the room's floor and walls;
- the user's errors in what they tell the tracker (``user_start``, ``tape_measure``): tape-measured segment
  lengths off by up to +-5 % each, the start position off by up to 10 cm, the heading by up to 10 degrees,
  the speed by up to 20 %, no step length and no stance leg.

``make_recording`` renders a recording once, seen by two cameras with ``BACKGROUND_FRAMES`` empty frames
before the person, and derives the four sequences a run tracks (``VARIANTS``): one or two cameras, each
hand-started (the empty frames, a start and a body description) or hands off (no empty frames, no
descriptions: the automatic start). Units: m, s, rad unless a name says otherwise.
"""
from __future__ import annotations

import json
import shutil
import sys
import zlib
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from awalker_tracker.errors import InputError
from awalker_tracker.model.acclaim import EXTRA_POINTS
from awalker_tracker.model.body import MARKER_NAMES, BodyDescription
from awalker_tracker.vision.camera import Camera, save_calibration

from awalker_tools import bagio, walk_variants
from awalker_tools.person_render import Outfit, PersonRenderer
from awalker_tools.synth import (
    FIRST_STAMP_NS,
    Lighting,
    Motion,
    Scene,
    make_textures,
    render_room,
    write_sequence,
)

MOCAP_ROOT = Path(__file__).resolve().parents[3] / "test" / "data" / "mocap"
_M = {n: i for i, n in enumerate(MARKER_NAMES)}
POINT_NAMES: tuple[str, ...] = MARKER_NAMES + tuple(EXTRA_POINTS)
#: Points of the upper body, scaled about the pelvis for the trunk-to-leg proportion.
UPPER_BODY = ("thorax", "head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist",
              "right_wrist", "left_hand", "right_hand", "neck", "head_top")
BACKGROUND_FRAMES = 15          # empty frames before the person in the hand-started sequences
ROOM_HALF_SIZE = 12.0           # m: cameras stand up to 10 m from the middle of the walk
MIN_CAMERA_CLEARANCE = 1.5      # m: no camera stands nearer than this to the pelvis's path
SECOND_PERSON_BEHIND_M = 1.2    # m: the second person's path behind the first's, as the first camera sees them
VIEW_OFF_LINE = np.radians(15.0)  # rad: cameras stand at least this far off the line the walk starts along


def off_the_walking_line(direction: float, heading: float) -> float:
    """A camera ``direction`` (rad, from the middle of the walk) moved, if needed, to ``VIEW_OFF_LINE`` from the
    line along ``heading``: nearly frontal (or from behind) at most, never straight along the walk."""
    off = float(np.angle(np.exp(1j * (direction - heading))))         # -pi..pi from the walking direction
    side = 1.0 if off >= 0 else -1.0
    return heading + side * float(np.clip(abs(off), VIEW_OFF_LINE, np.pi - VIEW_OFF_LINE))


@dataclass(frozen=True)
class Trial:
    """A stretch of a CMU trial: ``seconds`` (start, end) from the file's start (None: all of it), and a bend
    (``walk_variants.bend``: angle deg, start s, duration s after the stretch's start) for our own turned
    variants of straight walks."""

    name: str
    subject: str
    amc: str                              # file name in test/data/mocap/cmu_subject<subject>/
    what: str
    turns: bool = False
    seconds: tuple[float, float] | None = None
    bend: tuple[float, float, float] | None = None

    @property
    def asf_path(self) -> Path:
        return MOCAP_ROOT / f"cmu_subject{self.subject}" / f"{self.subject}.asf"

    @property
    def amc_path(self) -> Path:
        return MOCAP_ROOT / f"cmu_subject{self.subject}" / self.amc


TRIALS: dict[str, Trial] = {t.name: t for t in (
    Trial("05_01", "05", "05_01.amc", "walk, a right turn beginning in the last 0.5 s"),
    Trial("07_01", "07", "07_01.amc", "walk, straight, 1.4 m/s"),
    Trial("07_02", "07", "07_02.amc", "walk, straight, 1.3 m/s"),
    Trial("07_04", "07", "07_04.amc", "slow walk, 0.9 m/s"),
    Trial("07_01-uturn", "07", "07_01.amc", "07_01 turned round to the left within 2 s (bent)", True,
          bend=(180.0, 0.6, 2.0)),
    Trial("07_02-veer", "07", "07_02.amc", "07_02 veering 35 degrees to the right over 1.5 s (bent)", True,
          bend=(-35.0, 0.5, 1.5)),
    Trial("09_12", "09", "09_12.amc", "walk, a curved U-turn to the left (radius ~0.7 m), walk back", True,
          seconds=(0.0, 7.0)),
    Trial("29_01", "29", "29_01.amc", "stands, walks 1.9 m slowly, turns round on the spot, walks back", True),
    Trial("35_01", "35", "35_01.amc", "walk, straight, 1.3 m/s"),
    Trial("49_01", "49", "49_01.amc", "walk, straight, 0.9 m/s"),
    Trial("69_01", "69", "69_01.amc", "starts from standing, walks on at 0.95 m/s"),
    Trial("69_02", "69", "69_02.amc", "walk forward, 0.9 m/s"),
    Trial("91_10", "91", "91_10.amc", "small subject: slow walk (0.5 m/s), slows, turns round, pauses, walks back",
          True, seconds=(2.5, 20.0)),
    Trial("91_13", "91", "91_13.amc", "small subject, slumped: slow walk, turns round, pauses, walks back", True,
          seconds=(2.5, 17.5)),
    Trial("91_36", "91", "91_36.amc", "small subject: starts, walks 4.4 m at 0.8 m/s, stops"),
)}
#: The subjects a setting may be tuned on, and the ones accuracy is reported on (chosen before measuring).
TUNING_SUBJECTS = ("07", "35", "69", "91")
REPORTING_SUBJECTS = ("05", "09", "29", "49")
#: A small tuning subset for frequent runs: a straight walk, a turn and a start from standing.
QUICK = ("07_01", "07_01-uturn", "69_01")
#: The sequences a recording gives: name -> (cameras, hand-started).
VARIANTS = {"mono": (1, True), "two": (2, True), "mono_handsoff": (1, False), "two_handsoff": (2, False)}


def trials_of(which: str) -> list[str]:
    """Trial names of a set: "tuning", "reporting", "quick" or "all"."""
    if which == "quick":
        return list(QUICK)
    subjects = {"tuning": TUNING_SUBJECTS, "reporting": REPORTING_SUBJECTS,
                "all": TUNING_SUBJECTS + REPORTING_SUBJECTS}.get(which)
    if subjects is None:
        raise InputError(f"development set: unknown set {which!r}; expected tuning, reporting, quick or all")
    return [name for name, trial in TRIALS.items() if trial.subject in subjects]


# ---- the draws ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class CameraDraw:
    """Where a camera stands: its direction from the middle of the walk (rad from world +x), horizontal
    distance and height (m), horizontal field of view (deg, before widening to fit the walk), lens distortion."""

    direction: float
    distance_m: float
    height_m: float
    fov_deg: float
    k1: float


@dataclass(frozen=True)
class Recording:
    """Everything drawn for one run (module docstring)."""

    trial: str
    seed: int
    rate: float
    size: tuple[int, int]
    heading: float                       # the walk's first direction in the room (rad)
    scale: float                         # the whole skeleton
    trunk_scale: float                   # the upper body about the pelvis
    cameras: tuple[CameraDraw, CameraDraw]
    lighting: Lighting
    blur_px: float
    outfit: Outfit
    tape: tuple[float, ...]              # factors of the tape-measured lengths (TAPE_LENGTHS)
    start_offset_m: tuple[float, float]
    heading_error: float                 # rad
    speed_factor: float
    span: tuple[float, float] | None = None   # s of the trial's stretch to use (None: all of it)
    # another person walking this trial the other way, SECOND_PERSON_BEHIND_M farther from the first camera
    # (crossing behind the first person), in other clothes; the truth and the descriptions stay the first's
    second: str | None = None

    @classmethod
    def draw(cls, trial: str, seed: int) -> "Recording":
        """The recording of ``trial`` for run ``seed`` (the same seed draws the same recording)."""
        if trial not in TRIALS:
            raise InputError(f"development set: unknown trial {trial!r}; expected one of {', '.join(TRIALS)}")
        rng = np.random.default_rng([seed, zlib.crc32(trial.encode())])
        heading = float(rng.uniform(-np.pi, np.pi))
        first = heading + float(rng.choice([-1.0, 1.0])) * float(rng.uniform(VIEW_OFF_LINE, np.pi - VIEW_OFF_LINE))
        second = off_the_walking_line(
            first + float(rng.choice([-1.0, 1.0])) * float(rng.uniform(np.radians(45), np.radians(135))), heading)
        cameras = tuple(CameraDraw(direction=d, distance_m=float(rng.uniform(3.0, 10.0)),
                                   height_m=float(rng.uniform(0.8, 3.0)), fov_deg=float(rng.uniform(50.0, 75.0)),
                                   k1=float(rng.uniform(-0.08, 0.02))) for d in (first, second))
        lighting = Lighting(exposure=float(rng.uniform(0.65, 1.15)),
                            tint=tuple(float(v) for v in rng.uniform(0.92, 1.08, 3)),
                            change=float(rng.uniform(0.0, 0.3)), noise_sigma=float(rng.uniform(1.0, 6.0)))
        radius, angle = 0.10 * np.sqrt(rng.random()), rng.uniform(0, 2 * np.pi)
        return cls(trial=trial, seed=int(seed), rate=float(rng.choice([30.0, 60.0])),
                   size=((640, 480), (1280, 720))[int(rng.integers(2))], heading=heading,
                   scale=float(rng.uniform(0.92, 1.08)), trunk_scale=float(rng.uniform(0.93, 1.07)),
                   cameras=cameras, lighting=lighting, blur_px=float(rng.uniform(0.4, 1.2)),
                   outfit=Outfit.draw(rng),
                   tape=tuple(float(v) for v in rng.uniform(0.95, 1.05, len(TAPE_LENGTHS))),
                   start_offset_m=(float(radius * np.cos(angle)), float(radius * np.sin(angle))),
                   heading_error=float(np.radians(rng.uniform(-10.0, 10.0))), speed_factor=float(rng.uniform(0.8, 1.2)))

    def describe(self) -> dict:
        """The draws as plain data (recording.yaml)."""
        out = asdict(replace(self, outfit=None, lighting=None))
        out.pop("outfit"), out.pop("lighting")
        out["outfit"] = self.outfit.describe()
        out["lighting"] = asdict(self.lighting)
        return json.loads(json.dumps(out))


#: Body description lengths a user measures with a tape (``Recording.tape``).
TAPE_LENGTHS = ("upper_leg_length", "lower_leg_length", "hip_width", "torso_length", "foot_length", "head_length")


# ---- motion -------------------------------------------------------------------------------------
def trial_points(trial: Trial, rate: float) -> np.ndarray:
    """The trial's points (F, len(POINT_NAMES), 3) at ``rate`` Hz, the floor levelled at z = 0."""
    from awalker_tracker.model.acclaim import load_mocap

    if not trial.amc_path.is_file() or not trial.asf_path.is_file():
        raise InputError(f"development set: {trial.amc_path} or {trial.asf_path} missing (test/data/mocap/README.md)")
    mocap = load_mocap(trial.asf_path, trial.amc_path)
    points = np.concatenate([mocap.markers, mocap.extra], axis=1)
    if trial.seconds is not None:
        first, last = (int(round(s * mocap.rate)) for s in trial.seconds)
        points = points[first: last + 1]
    resampled = replace(mocap, markers=points[:, : len(MARKER_NAMES)], extra=points[:, len(MARKER_NAMES):]).resample(rate)
    return walk_variants.level_floor(np.concatenate([resampled.markers, resampled.extra], axis=1), rate)


def walking_onset(pelvis: np.ndarray, rate: float, moving_m_s: float = 0.3) -> int:
    """First frame from which the pelvis moves faster than ``moving_m_s`` over the next half second (0 if it
    never does)."""
    window = max(1, int(round(0.5 * rate)))
    if len(pelvis) <= window:
        return 0
    speed = np.linalg.norm(pelvis[window:, :2] - pelvis[:-window, :2], axis=1) / (window / rate)
    moving = np.flatnonzero(speed > moving_m_s)
    return int(moving[0]) if moving.size else 0


def walk_direction_and_speed(pelvis: np.ndarray, rate: float) -> tuple[float, float, int]:
    """(heading rad, speed m/s, onset frame) of a walk's start as a user states it: the direction and mean speed
    over the first 1.5 s once the person walks (``walking_onset``)."""
    onset = walking_onset(pelvis, rate)
    end = min(len(pelvis) - 1, onset + int(round(1.5 * rate)))
    ahead = pelvis[end, :2] - pelvis[onset, :2]
    duration = max(end - onset, 1) / rate
    return float(np.arctan2(ahead[1], ahead[0])), float(np.linalg.norm(ahead) / duration), onset


def recording_motion(recording: Recording) -> Motion:
    """The recording's motion: the trial scaled, bent, and placed in the room (the middle of the walk at the
    origin, its first direction along ``recording.heading``); body sizes from the markers; the true start."""
    from awalker_tracker.model.acclaim import body_from_markers, segments_from_markers

    trial, rate = TRIALS[recording.trial], recording.rate
    points = trial_points(trial, rate)
    if recording.span is not None:
        first, last = (int(round(s * rate)) for s in recording.span)
        points = points[first: last + 1]
    pelvis0 = points[0, _M["pelvis"]] * np.array([1.0, 1.0, 0.0])
    points = (points - pelvis0) * recording.scale
    upper = [POINT_NAMES.index(n) for n in UPPER_BODY]
    pelvis = points[:, _M["pelvis"]][:, None]
    points[:, upper] = pelvis + recording.trunk_scale * (points[:, upper] - pelvis)
    direction, _, _ = walk_direction_and_speed(points[:, _M["pelvis"]], rate)
    c, s = np.cos(recording.heading - direction), np.sin(recording.heading - direction)
    points = points @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T
    if trial.bend is not None:
        angle, start, duration = trial.bend
        points = walk_variants.bend(points, rate, np.radians(angle), start, duration)
    path = points[:, _M["pelvis"], :2]
    points -= np.append(0.5 * (path.min(axis=0) + path.max(axis=0)), 0.0)
    markers = np.ascontiguousarray(points[:, : len(MARKER_NAMES)])
    body = body_from_markers(markers)
    heading, speed, _ = walk_direction_and_speed(markers[:, _M["pelvis"]], rate)
    start = {"start": {"frame": BACKGROUND_FRAMES,
                       "position": [round(float(v), 4) for v in markers[0, _M["pelvis"], :2]],
                       "heading": round(heading, 4), "speed": round(max(speed, 0.3), 4), "stance_leg": "unknown"}}
    return Motion(markers, segments_from_markers(body, markers), body, None, start, points)


def user_start(recording: Recording, start: dict) -> dict:
    """The start description as the user writes it: the truth with the recording's errors, no step length,
    no stance leg."""
    s = dict(start["start"])
    s["position"] = [round(float(s["position"][k] + recording.start_offset_m[k]), 3) for k in (0, 1)]
    s["heading"] = round(float(s["heading"] + recording.heading_error), 3)
    s["speed"] = round(float(s["speed"] * recording.speed_factor), 2)
    s.pop("step_length", None)
    s["stance_leg"] = "unknown"
    return {"start": s}


def second_person(recording: Recording, first: Motion) -> Motion:
    """The second person of ``recording``: its ``second`` trial walked the other way (the first's heading turned
    round), its path's middle ``SECOND_PERSON_BEHIND_M`` behind the first's as the first camera looks, as many
    frames as the first's (the walk repeated if shorter)."""
    motion = recording_motion(replace(recording, trial=recording.second, heading=recording.heading + np.pi,
                                      span=None, second=None))
    points = motion.points
    if len(points) < len(first.points):
        points = walk_variants.loop_to_duration(points, recording.rate, (len(first.points) - 1) / recording.rate)
    points = points[: len(first.points)].copy()
    toward_camera = np.array([np.cos(recording.cameras[0].direction), np.sin(recording.cameras[0].direction)])
    path = first.points[:, _M["pelvis"], :2]
    middle = 0.5 * (path.min(axis=0) + path.max(axis=0))
    points[..., :2] += middle - SECOND_PERSON_BEHIND_M * toward_camera
    markers = np.ascontiguousarray(points[:, : len(MARKER_NAMES)])
    return replace(motion, markers=markers, points=points)


def tape_measure(recording: Recording, body: BodyDescription) -> BodyDescription:
    """The body description as the user measures it: each of ``TAPE_LENGTHS`` x the recording's factor."""
    return replace(body, **{n: round(getattr(body, n) * f, 3) for n, f in zip(TAPE_LENGTHS, recording.tape)})


# ---- cameras ------------------------------------------------------------------------------------
def draw_camera(name: str, draw: CameraDraw, size: tuple[int, int], points: np.ndarray) -> Camera:
    """The camera of ``draw`` aimed at the middle of the walk at hip height, moved back until it stands
    ``MIN_CAMERA_CLEARANCE`` from the pelvis's path, its field of view widened (up to 110 degrees, then the
    camera moved back) until every point of the person (``points`` (F, P, 3)) lies inside the image's inner
    90 %."""
    width, height = size
    path = points[:, _M["pelvis"], :2]
    centre = 0.5 * (path.min(axis=0) + path.max(axis=0))
    away = np.array([np.cos(draw.direction), np.sin(draw.direction)])
    distance = draw.distance_m
    while np.min(np.linalg.norm(path - (centre + distance * away), axis=1)) < MIN_CAMERA_CLEARANCE:
        distance += 0.25
    sample = points[:: max(1, len(points) // 200)].reshape(-1, 3)
    fov = draw.fov_deg
    for _ in range(200):
        focal = 0.5 * width / np.tan(np.radians(0.5 * fov))
        position = np.append(centre + distance * away, draw.height_m)
        camera = Camera.look_at(name, width, height, focal, position, np.append(centre, 0.9),
                                distortion=np.array([draw.k1, 0.0, 0.0, 0.0, 0.0]))
        uv, depth = camera.project(sample)
        inside = (np.all(depth > 0.1) and np.all(np.isfinite(uv))
                  and np.all((uv[:, 0] > 0.05 * width) & (uv[:, 0] < 0.95 * width))
                  and np.all((uv[:, 1] > 0.05 * height) & (uv[:, 1] < 0.95 * height)))
        if inside:
            return camera
        if fov < 110.0:
            fov = min(110.0, fov + 5.0)
        else:
            distance += 0.5
    raise InputError(f"development set: camera {name} cannot see the whole walk ({draw})")


# ---- rendering ----------------------------------------------------------------------------------
def make_recording(recording: Recording, out: Path, progress: bool = True) -> dict[str, Path]:
    """Render ``recording`` into ``out`` (created) and derive its sequences: ``out/<variant>/synth.bag`` for each
    of ``VARIANTS`` with calibration.yaml, ground_truth.csv and, hand-started, start.yaml and body.yaml;
    ``out/recording.yaml`` (the draws) and ``out/ground_truth_body.yaml``. Returns variant -> bag. Reuses
    what an earlier call left for the same draws (``out/done`` holds them)."""
    out = Path(out)
    bags = {variant: out / variant / "synth.bag" for variant in VARIANTS}
    draws = json.dumps(recording.describe(), sort_keys=True)
    if (out / "done").is_file() and (out / "done").read_text() == draws:
        return bags
    if out.exists():
        shutil.rmtree(out)
    master = out / "master"
    master.mkdir(parents=True)
    motion = recording_motion(recording)
    rng = np.random.default_rng([recording.seed, zlib.crc32(recording.trial.encode()), 1])
    other = second_person(recording, motion) if recording.second is not None else None
    seen = motion.points if other is None else np.concatenate([motion.points, other.points], axis=1)
    cameras = [draw_camera(f"cam{k}", draw, recording.size, seen) for k, draw in enumerate(recording.cameras)]
    textures = make_textures(rng, ROOM_HALF_SIZE)
    painters = {cam.name: PersonRenderer(cam, recording.outfit, blur_sigma_px=0.0) for cam in cameras}
    scene = Scene(cameras, [render_room(cam, textures, ROOM_HALF_SIZE) for cam in cameras], painters=painters,
                  blur_px=recording.blur_px, other=other)
    if other is not None:
        outfit = Outfit.draw(rng)
        scene.other_painters = {cam.name: PersonRenderer(cam, outfit, blur_sigma_px=0.0) for cam in cameras}
    body = tape_measure(recording, motion.body)
    start = user_start(recording, motion.start)
    start_text, body_text = yaml.safe_dump(start, sort_keys=False), body.to_yaml_text()
    if progress:
        print(f"devset: rendering {recording.trial} seed {recording.seed}: {len(motion.markers)} frames at "
              f"{recording.rate:g} Hz, {recording.size[0]}x{recording.size[1]}", file=sys.stderr, flush=True)
    write_sequence(master, "synth", motion, scene, recording.lighting, recording.rate, BACKGROUND_FRAMES, rng,
                   start_text=start_text, body_text=body_text, progress=progress)
    first_person_ns = int(FIRST_STAMP_NS + round(BACKGROUND_FRAMES * 1e9 / recording.rate))
    for variant, (count, hand_started) in VARIANTS.items():
        seq = out / variant
        seq.mkdir()
        kept = [cam.name for cam in cameras[:count]]
        bagio.copy_bag(master / "synth.bag", bags[variant], cameras=kept,
                       start_ns=None if hand_started else first_person_ns, descriptions=hand_started)
        save_calibration(cameras[:count], seq / "calibration.yaml")
        for csv in ("ground_truth.csv", "second_person.csv"):
            if not (master / csv).is_file():
                continue
            truth = (master / csv).read_text()
            if not hand_started:       # frames count from the first frame of the bag
                truth = _shift_frames(truth, -BACKGROUND_FRAMES)
            (seq / csv).write_text(truth)
        if hand_started:
            (seq / "start.yaml").write_text(start_text)
            (seq / "body.yaml").write_text(body_text)
    (out / "ground_truth_body.yaml").write_text(motion.body.to_yaml_text())
    info = recording.describe()
    info["true_start"] = motion.start["start"]
    info["cameras_placed"] = [{"name": c.name, "position": [round(float(v), 3) for v in c.position],
                               "focal_px": round(float(c.K[0, 0]), 1)} for c in cameras]
    (out / "recording.yaml").write_text(yaml.safe_dump(info, sort_keys=False))
    shutil.rmtree(master / "synth.bag")
    (out / "done").write_text(draws)
    return bags


def _shift_frames(csv_text: str, by: int) -> str:
    """ground_truth.csv with its frame column moved by ``by``."""
    lines = csv_text.splitlines()
    out = [lines[0]]
    for line in lines[1:]:
        frame, rest = line.split(",", 1)
        out.append(f"{int(frame) + by},{rest}")
    return "\n".join(out) + "\n"
