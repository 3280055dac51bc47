"""Per-frame posterior summaries of the particle set (paper Sec. 5.2 and the figures of Sec. 6).

The tracker model turns its particle states into ``ParticleOutputs`` (plain arrays, one row per
particle); ``summarize`` reduces them with the filter weights to what the tracker publishes:
MAP and weighted-mean pose, walking speed (mean, std), the probability that the left leg is
the stance leg, N_eff, foot contacts with heel strikes, and weighted clouds of a few markers.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from scipy.spatial.transform import Rotation

from awalker_tracker.inference.gait_events import Step

LEFT, RIGHT = 0, 1
CLOUD_MARKERS = ("head", "pelvis", "left_knee", "right_knee", "left_ankle", "right_ankle")
WALKER_FIELDS = ("stance_angle", "swing_angle", "stance_rate", "swing_rate", "contact_origin",
                 "stiffness", "stiffness_mean_mean", "stiffness_mean_variance", "toe_off_impulse")


@dataclass
class ParticleOutputs:
    """What every particle reports at one frame (arrays with leading axis N)."""

    markers: np.ndarray            # (N, M, 3) world (m), M = len(marker_names)
    joint_angles: np.ndarray       # (N, J) rad
    torso_position: np.ndarray     # (N, 3) pelvis position, world (m)
    torso_rotation: np.ndarray     # (N, 3, 3) pelvis orientation, world_from_pelvis (columns forward, left, up)
    speed: np.ndarray              # (N,) walking speed (m/s), averaged over about one step
    stance_leg: np.ndarray         # (N,) LEFT / RIGHT
    contact_point: np.ndarray      # (N, 3) stance foot's ground contact, world (m)
    heel_strike: np.ndarray        # (N,) bool: the swing foot struck the ground during this frame
    strike_point: np.ndarray       # (N, 3) where it struck (valid where heel_strike), world (m)
    strike_fraction: np.ndarray    # (N,) when in the frame it struck, 0-1 of the frame period (NaN where none)
    walker: dict[str, np.ndarray]  # WALKER_FIELDS -> (N,) walker and control state
    reseeded: np.ndarray           # (N,) int8: 0, or re-seeded this frame: 1 after a fall, 2 at the detected person,
                                   # 3 held where it stood (the person stands still; inference.recovery)

    def take(self, indices: np.ndarray) -> "ParticleOutputs":
        values = {}
        for f in fields(self):
            v = getattr(self, f.name)
            values[f.name] = {k: a[indices] for k, a in v.items()} if isinstance(v, dict) else v[indices]
        return ParticleOutputs(**values)


@dataclass(frozen=True)
class FootContactEstimate:
    foot: int                       # LEFT / RIGHT
    position: np.ndarray            # (3,) weighted mean contact point of particles standing on this foot (m)
    probability: float              # posterior probability that this foot is the stance foot
    heel_strike: bool               # posterior probability of a strike by this foot this frame > 0.5


@dataclass(frozen=True)
class MarkerCloud:
    marker_name: str
    points: np.ndarray              # (K, 3) world (m)
    weights: np.ndarray             # (K,) normalised over the full particle set


@dataclass(frozen=True)
class PosteriorSummary:
    """The tracker's output for one frame (mirrors awalker_msgs/PosteriorSummary)."""

    frame_index: int
    stamp_ns: int
    marker_names: tuple[str, ...]
    joint_names: tuple[str, ...]
    map_markers: np.ndarray         # (M, 3) highest-weight particle
    mean_markers: np.ndarray        # (M, 3) weighted mean
    map_joint_angles: np.ndarray    # (J,)
    map_torso_position: np.ndarray  # (3,)
    map_torso_orientation: np.ndarray  # (4,) x, y, z, w
    map_stance_leg: int
    map_walker: dict[str, float]
    speed: float
    speed_std: float
    stance_left_probability: float
    effective_sample_size: float
    num_particles: int
    resampled: bool
    contacts: tuple[FootContactEstimate, ...]
    clouds: tuple[MarkerCloud, ...]
    reseeded_fallen: int = 0        # particles re-seeded at this frame after their walker fell
    reacquired: int = 0             # particles re-seeded at this frame at the person seen in the images
    person_still: bool = False      # the person stood still at this frame: the walkers were held
    track_id: int = 1               # which track of the run (a new one each time a person is found anew)
    person_in_view: bool = True     # in view of some camera (inference.visibility; True without images)
    cameras_in_view: tuple[str, ...] = ()   # the cameras that see the person
    legs_renamed: bool = False      # every particle renamed its legs at this frame (the naming test): the stance
                                    # foot's name changed, the foot did not
    steps: tuple[Step, ...] = ()    # the steps the MAP lineage settled at this frame
                                    # (Tracker.lineage_steps), timed in s of the stamps' clock (time_s = stamp_ns / 1e9)

    @property
    def heel_strike_foot(self) -> str:
        """'left', 'right' or '' (summary.csv column)."""
        struck = [c.foot for c in self.contacts if c.heel_strike]
        return "" if not struck else ("left" if struck[0] == LEFT else "right")


def summarize(frame_index: int, stamp_ns: int, log_weights: np.ndarray, outputs: ParticleOutputs,
              marker_names: tuple[str, ...], joint_names: tuple[str, ...], resampled: bool,
              cloud_size: int = 200, cloud_markers: tuple[str, ...] = CLOUD_MARKERS) -> PosteriorSummary:
    """Reduce a weighted particle set to a PosteriorSummary.

    Clouds hold the ``cloud_size`` highest-weight particles (weights as in the full set).
    """
    w = np.exp(log_weights - np.max(log_weights))
    w /= w.sum()
    n = w.size
    best = int(np.argmax(w))
    mean_markers = np.einsum("n,nmk->mk", w, outputs.markers)
    speed = float(np.sum(w * outputs.speed))
    speed_std = float(np.sqrt(max(0.0, np.sum(w * (outputs.speed - speed) ** 2))))
    left = outputs.stance_leg == LEFT
    contacts = []
    for foot, on_foot in ((LEFT, left), (RIGHT, ~left)):
        p = float(np.sum(w[on_foot]))
        position = (np.einsum("n,nk->k", w[on_foot], outputs.contact_point[on_foot]) / p if p > 0
                    else np.full(3, np.nan))
        # the swing foot of a particle standing on the other foot strikes: the new stance leg is `foot`
        struck = outputs.heel_strike & on_foot
        contacts.append(FootContactEstimate(foot, position, p, bool(np.sum(w[struck]) > 0.5)))
    k = min(cloud_size, n)
    top = np.argpartition(-w, k - 1)[:k] if k < n else np.arange(n)
    clouds = tuple(MarkerCloud(name, outputs.markers[top, marker_names.index(name)].copy(), w[top].copy())
                   for name in cloud_markers if name in marker_names)
    return PosteriorSummary(
        frame_index=int(frame_index), stamp_ns=int(stamp_ns), marker_names=tuple(marker_names),
        joint_names=tuple(joint_names), map_markers=outputs.markers[best].copy(), mean_markers=mean_markers,
        map_joint_angles=outputs.joint_angles[best].copy(),
        map_torso_position=outputs.torso_position[best].copy(),
        map_torso_orientation=Rotation.from_matrix(outputs.torso_rotation[best]).as_quat(),
        map_stance_leg=int(outputs.stance_leg[best]),
        map_walker={k: float(v[best]) for k, v in outputs.walker.items()},
        speed=speed, speed_std=speed_std, stance_left_probability=float(np.sum(w[left])),
        effective_sample_size=float(1.0 / np.sum(w * w)), num_particles=n, resampled=bool(resampled),
        contacts=tuple(contacts), clouds=clouds, reseeded_fallen=int(np.sum(outputs.reseeded == 1)),
        reacquired=int(np.sum(outputs.reseeded == 2)), person_still=bool(np.any(outputs.reseeded == 3)))
