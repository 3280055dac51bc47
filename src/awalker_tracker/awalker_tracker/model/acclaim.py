"""CMU/Acclaim motion capture (ASF skeleton + AMC motion) -> our 13 markers in the world frame.

Forward kinematics (the Acclaim convention, see test/data/mocap/README.md): a bone's
global rotation is ``parent * C * M * C^-1`` with C from its ``axis`` angles and M = Rz Ry Rx
from its DOF values (degrees); its end is its parent's end plus ``length * rotation @
direction``. The root's rotation uses its ``orientation`` as C and the root DOFs; its
position is the root translation. ASF units are ``length`` per inch (07.asf: 0.45), so metres
= value * 0.0254 / length. The ASF frame is Y up; our world is z up: (x, y, z)_world =
(x, -z, y)_asf * scale.

Markers (``MARKER_NAMES``): hips = ends of l/rhipjoint (hip joint centres), pelvis = their
midpoint, knees = femur ends, ankles = tibia ends, toes = toes ends, thorax = thorax end (neck
base), head = midpoint of the lowerneck end and the head end, heels = a point fixed in the
foot frame ``heel_offset`` behind the ankle at the toe end's rest height (the skeleton has
no heel joint). Source rate: 120 Hz.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from awalker_tracker.errors import InputError
from awalker_tracker.model.body import MARKER_NAMES, BodyDescription, BodySegments

MOCAP_RATE = 120.0
_ASF_TO_WORLD = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclass
class _Bone:
    name: str
    direction: np.ndarray
    length: float
    axis: np.ndarray        # C (3, 3)
    dofs: list[str] = field(default_factory=list)


@dataclass
class Skeleton:
    """An ASF skeleton: bones, hierarchy (child -> parent), root DOF order and axis, unit scale (m)."""

    bones: dict[str, _Bone]
    parent: dict[str, str]
    root_order: list[str]
    root_axis: np.ndarray
    scale: float  # metres per ASF length unit
    angle_scale: float  # rad per ASF angle unit


def _euler(angles_deg: np.ndarray, order: str = "XYZ", angle_scale: float = np.pi / 180) -> np.ndarray:
    """R = R_last ... R_first for ``order`` (e.g. XYZ -> Rz Ry Rx), angles (..., 3) in ASF units."""
    angles = np.asarray(angles_deg, float) * angle_scale
    out = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3)).copy()
    for letter in order:
        axis = "XYZ".index(letter.upper())
        a = angles[..., axis]
        c, s = np.cos(a), np.sin(a)
        r = np.zeros(a.shape + (3, 3))
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        r[..., axis, axis] = 1.0
        r[..., i, i] = c
        r[..., j, j] = c
        r[..., i, j] = -s
        r[..., j, i] = s
        out = r @ out
    return out


def load_asf(path: str | Path) -> Skeleton:
    """Parse an Acclaim ASF skeleton file."""
    path = Path(path)
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError as exc:
        raise InputError(f"{path}: cannot read ASF skeleton ({exc.strerror})") from None
    length_unit, angle_scale = 1.0, np.pi / 180
    root_order: list[str] = []
    root_axis = np.eye(3)
    bones: dict[str, _Bone] = {}
    parent: dict[str, str] = {}
    section = ""
    current: dict[str, object] | None = None
    try:
        for raw in lines:
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            if line.startswith(":"):
                section = line.split()[0][1:]
                continue
            words = line.split()
            if section == "units":
                if words[0] == "length":
                    length_unit = float(words[1])
                elif words[0] == "angle":
                    angle_scale = 1.0 if words[1].startswith("rad") else np.pi / 180
            elif section == "root":
                if words[0] == "order":
                    root_order = [w.upper() for w in words[1:]]
                elif words[0] == "orientation":
                    root_axis = _euler(np.array([float(w) for w in words[1:4]]), "XYZ", angle_scale)
            elif section == "bonedata":
                if words[0] == "begin":
                    current = {"dofs": []}
                elif words[0] == "end" and current is not None:
                    bone = _Bone(str(current["name"]), np.asarray(current["direction"], float),
                                 float(current["length"]), current["axis"], list(current["dofs"]))
                    bones[bone.name] = bone
                    current = None
                elif current is not None:
                    if words[0] == "name":
                        current["name"] = words[1]
                    elif words[0] == "direction":
                        current["direction"] = [float(w) for w in words[1:4]]
                    elif words[0] == "length":
                        current["length"] = float(words[1])
                    elif words[0] == "axis":
                        order = words[4] if len(words) > 4 else "XYZ"
                        current["axis"] = _euler(np.array([float(w) for w in words[1:4]]), order, angle_scale)
                    elif words[0] == "dof":
                        current["dofs"] = [w.lower() for w in words[1:]]
            elif section == "hierarchy":
                if words[0] in ("begin", "end"):
                    continue
                for child in words[1:]:
                    parent[child] = words[0]
    except (ValueError, IndexError, KeyError) as exc:
        raise InputError(f"{path}: malformed ASF skeleton ({exc!r})") from None
    needed = ("lhipjoint", "rhipjoint", "lfemur", "rfemur", "ltibia", "rtibia", "lfoot", "rfoot", "ltoes",
              "rtoes", "thorax", "lowerneck", "head")
    missing = [b for b in needed if b not in bones or b not in parent]
    if missing or not root_order:
        raise InputError(f"{path}: not a CMU-style ASF skeleton (missing bones {missing or ''}"
                         f"{'' if root_order else ' and :root order'})")
    return Skeleton(bones, parent, root_order, root_axis, 0.0254 / length_unit, angle_scale)


def load_amc(path: str | Path, skeleton: Skeleton) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Parse an AMC motion: root values (F, 6) and per-bone DOF values {bone: (F, D)} (ASF units)."""
    path = Path(path)
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError as exc:
        raise InputError(f"{path}: cannot read AMC motion ({exc.strerror})") from None
    frames: list[dict[str, list[float]]] = []
    try:
        for raw in lines:
            line = raw.strip()
            if not line or line.startswith("#") or line.startswith(":"):
                continue
            words = line.split()
            if len(words) == 1 and words[0].isdigit():
                frames.append({})
                continue
            if not frames:
                raise ValueError(f"values before the first frame number: {line!r}")
            frames[-1][words[0]] = [float(w) for w in words[1:]]
    except ValueError as exc:
        raise InputError(f"{path}: malformed AMC motion ({exc})") from None
    if not frames:
        raise InputError(f"{path}: AMC motion holds no frames")
    try:
        root = np.array([f["root"] for f in frames], float)
        values = {}
        for name, bone in skeleton.bones.items():
            if bone.dofs:
                values[name] = np.array([f.get(name, [0.0] * len(bone.dofs)) for f in frames], float)
    except (KeyError, ValueError) as exc:
        raise InputError(f"{path}: AMC frames do not match the skeleton ({exc!r})") from None
    if root.ndim != 2 or root.shape[1] != len(skeleton.root_order):
        raise InputError(f"{path}: root lines must hold {len(skeleton.root_order)} values ({skeleton.root_order})")
    return root, values


def forward_kinematics(skeleton: Skeleton, root: np.ndarray, values: dict[str, np.ndarray]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Bone end positions (F, 3) and global rotations (F, 3, 3), in ASF coordinates and units."""
    order = skeleton.root_order
    position = np.stack([root[:, order.index(k)] for k in ("TX", "TY", "TZ")], axis=1)
    angles = np.stack([root[:, order.index(k)] for k in ("RX", "RY", "RZ")], axis=1)
    c = skeleton.root_axis
    root_rotation = c @ _euler(angles, "XYZ", skeleton.angle_scale) @ c.T
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {"root": (position, root_rotation)}

    def solve(name: str) -> tuple[np.ndarray, np.ndarray]:
        if name in out:
            return out[name]
        bone = skeleton.bones[name]
        parent_end, parent_rotation = solve(skeleton.parent[name])
        frames = parent_end.shape[0]
        dof_angles = np.zeros((frames, 3))
        for i, dof in enumerate(bone.dofs):
            dof_angles[:, "xyz".index(dof[1])] = values[name][:, i]
        local = bone.axis @ _euler(dof_angles, "XYZ", skeleton.angle_scale) @ bone.axis.T
        rotation = parent_rotation @ local
        end = parent_end + bone.length * (rotation @ bone.direction)
        out[name] = (end, rotation)
        return out[name]

    for name in skeleton.bones:
        solve(name)
    return out


# Skeleton points beyond the 13 markers (arms, neck, head top), for renderers that draw a whole person:
# name -> the ASF bone whose end it is.
EXTRA_POINTS: dict[str, str] = {
    "left_shoulder": "lclavicle", "right_shoulder": "rclavicle", "left_elbow": "lhumerus",
    "right_elbow": "rhumerus", "left_wrist": "lradius", "right_wrist": "rradius",
    "left_hand": "lhand", "right_hand": "rhand", "neck": "lowerneck", "head_top": "head",
}


@dataclass
class MocapTrial:
    """Marker trajectories (F, 13, 3) in the world frame (z up, m) at ``rate`` Hz, and the skeleton's
    other points (F, len(EXTRA_POINTS), 3) in ``EXTRA_POINTS`` order (arms, neck, head top)."""

    markers: np.ndarray
    rate: float
    source: str = ""
    extra: np.ndarray | None = None

    @property
    def duration(self) -> float:
        return (self.markers.shape[0] - 1) / self.rate

    def resample(self, rate: float) -> "MocapTrial":
        """Linear interpolation in time to ``rate`` Hz (exact subsampling when it divides 120)."""
        if rate <= 0:
            raise ValueError(f"resample: rate must be > 0 Hz, got {rate}")
        times = np.arange(0.0, self.duration + 1e-9, 1.0 / rate)
        source = np.arange(self.markers.shape[0]) / self.rate

        def interp(points: np.ndarray) -> np.ndarray:
            flat = points.reshape(points.shape[0], -1)
            out = np.stack([np.interp(times, source, flat[:, k]) for k in range(flat.shape[1])], axis=1)
            return out.reshape(len(times), *points.shape[1:])

        return MocapTrial(interp(self.markers), float(rate), self.source,
                          None if self.extra is None else interp(self.extra))


def load_mocap(asf: str | Path, amc: str | Path, heel_offset: float = 0.05) -> MocapTrial:
    """Load a CMU walk as our 13 markers (world frame, z up, m) at 120 Hz."""
    skeleton = load_asf(asf)
    root, values = load_amc(amc, skeleton)
    bones = forward_kinematics(skeleton, root, values)
    end = {name: pos for name, (pos, _) in bones.items()}
    # Heel: fixed in the foot frame, behind the ankle at the toe end's rest height (ASF units).
    heels = []
    for side in "lr":
        foot, toes = skeleton.bones[f"{side}foot"], skeleton.bones[f"{side}toes"]
        toe_rest = foot.length * foot.direction + toes.length * toes.direction
        forward = toe_rest * np.array([1.0, 0.0, 1.0])
        forward /= np.linalg.norm(forward)
        heel_rest = np.array([0.0, toe_rest[1], 0.0]) - forward * heel_offset / skeleton.scale
        heels.append(end[f"{side}tibia"] + bones[f"{side}foot"][1] @ heel_rest)
    hips = (end["lhipjoint"], end["rhipjoint"])
    markers_asf = np.stack([
        0.5 * (hips[0] + hips[1]), end["thorax"], 0.5 * (end["lowerneck"] + end["head"]),
        hips[0], hips[1], end["lfemur"], end["rfemur"], end["ltibia"], end["rtibia"],
        heels[0], heels[1], end["ltoes"], end["rtoes"],
    ], axis=1)
    assert markers_asf.shape[1] == len(MARKER_NAMES)
    markers = (markers_asf @ _ASF_TO_WORLD.T) * skeleton.scale
    extra = np.stack([end[bone] for bone in EXTRA_POINTS.values()], axis=1) @ _ASF_TO_WORLD.T * skeleton.scale
    return MocapTrial(markers, MOCAP_RATE, f"{Path(asf).name}+{Path(amc).name}", extra)


def flat_foot_frames(markers: np.ndarray, side: str) -> np.ndarray:
    """(F,) bool: the frames of marker trajectories (F, 13, 3) in which the ``side`` foot lies flat on the
    floor: heel and toe within 1 cm of each other in height, and of those the lower half (a foot held
    level in the swing is higher)."""
    heel, toe = (markers[:, MARKER_NAMES.index(f"{side}_{name}"), 2] for name in ("heel", "toe"))
    level = np.abs(heel - toe) < 0.01
    if not level.any():
        return level
    line = 0.5 * (heel + toe)
    return level & (line <= np.median(line[level]))


def body_from_markers(markers: np.ndarray, template: BodyDescription | None = None) -> BodyDescription:
    """A body description with segment sizes measured from marker trajectories (F, 13, 3) with the floor
    at z = 0 (``walk_variants.level_floor``), medians over frames; widths and the other sizes from
    ``template``.

    The ankle's height over the floor while its foot lies flat on it (``flat_foot_frames``) is what a tape
    measure gives; the body stands on
    its rocker sole's middle, ``sole_sag`` below the sole line, so ``ankle_height`` is that height less
    the sag, and ``leg_length`` is the person's standing hip height. ``heel_offset`` is how far the heel
    lies behind the ankle along the heel-toe line. CMU subject 7: the ankle 5.8-5.9 cm over the floor,
    the heel 5.1 cm behind it, where the template's ankle (6.6 cm, plus the 1 cm sag) stood the body
    1.7 cm taller than the person drawn on those markers (``synth --person dressed``)."""
    template = template or BodyDescription.default()
    idx = {n: i for i, n in enumerate(MARKER_NAMES)}

    def length(a: str, b: str) -> float:
        return float(np.median(np.linalg.norm(markers[:, idx[a]] - markers[:, idx[b]], axis=-1)))

    def ankle_over_floor(side: str) -> float:
        flat = flat_foot_frames(markers, side)
        return float(np.median(markers[flat, idx[f"{side}_ankle"], 2])) if flat.any() else template.ankle_height

    def heel_behind(side: str) -> float:
        heel, toe, ankle = (markers[:, idx[f"{side}_{name}"]] for name in ("heel", "toe", "ankle"))
        along = toe - heel
        along /= np.maximum(np.linalg.norm(along, axis=-1, keepdims=True), 1e-12)
        return float(np.median(np.sum((ankle - heel) * along, axis=-1)))

    foot_length = 0.5 * (length("left_heel", "left_toe") + length("right_heel", "right_toe"))
    body = replace(
        template,
        upper_leg_length=0.5 * (length("left_hip", "left_knee") + length("right_hip", "right_knee")),
        lower_leg_length=0.5 * (length("left_knee", "left_ankle") + length("right_knee", "right_ankle")),
        heel_offset=float(np.clip(0.5 * (heel_behind("left") + heel_behind("right")), 0.01, 0.5 * foot_length)),
        hip_width=length("left_hip", "right_hip"),
        torso_length=length("pelvis", "thorax"),
        foot_length=foot_length,
    )
    # Standing on the rocker sole's middle, the body's ankle is ankle_height + sole_sag over the floor.
    over_floor = 0.5 * (ankle_over_floor("left") + ankle_over_floor("right"))
    return replace(body, ankle_height=float(np.clip(over_floor - body.sole_sag, template.foot_radii_heel[0], 0.15)))


def segments_from_markers(body: BodyDescription, markers: np.ndarray) -> BodySegments:
    """Part poses (N bodies) from markers (N, 13, 3): each part starts at its proximal marker
    and points at its distal one; ellipse axes from the pelvis's left-right direction."""
    idx = {n: i for i, n in enumerate(MARKER_NAMES)}
    m = lambda name: markers[:, idx[name]]  # noqa: E731
    lateral = m("left_hip") - m("right_hip")
    up = m("thorax") - m("pelvis")
    head_base = m("thorax")
    foot_lift = np.array([0.0, 0.0, body.foot_radii_heel[0]])
    starts_ends = [
        (m("pelvis"), m("thorax")),
        (head_base, head_base + up / np.linalg.norm(up, axis=-1, keepdims=True) * body.head_length),
        (m("left_hip"), m("left_knee")), (m("right_hip"), m("right_knee")),
        (m("left_knee"), m("left_ankle")), (m("right_knee"), m("right_ankle")),
        (m("left_heel") + foot_lift, m("left_toe") + foot_lift), (m("right_heel") + foot_lift, m("right_toe") + foot_lift),
    ]
    origins, rotations = [], []
    for k, (start, end) in enumerate(starts_ends):
        axis = end - start
        axis /= np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-12)
        is_foot = k >= 6
        # Column 0: forward for torso/head/legs (lateral x axis), up out of the foot for feet.
        col0 = np.cross(axis, lateral) if is_foot else np.cross(lateral, axis)
        col0 /= np.maximum(np.linalg.norm(col0, axis=-1, keepdims=True), 1e-12)
        col1 = np.cross(axis, col0)
        origins.append(start)
        rotations.append(np.stack([col0, col1, axis], axis=-1))
    return BodySegments(np.stack(origins, axis=1), np.stack(rotations, axis=1))
