"""Message <-> core conversions for poses and posterior summaries (awalker_msgs, rclpy types), and the
queue depth both ends of /awalker/posterior use.

Only conversions live here; no computation. Arrays go into float64[]/float32[] fields as
``array.array`` (fast; assigning numpy arrays element-wise is slow in rclpy).
"""
from __future__ import annotations

import array
from typing import TYPE_CHECKING

import numpy as np
from awalker_msgs.msg import BodyPose, FootContact, GaitStep, ParticleCloud, PosteriorSummary, WalkerState
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseStamped
from sensor_msgs.msg import CameraInfo, PointCloud2, PointField
from std_msgs.msg import Header

from awalker_tracker.inference import posterior as core
from awalker_tracker.inference.gait_events import Step

if TYPE_CHECKING:
    from awalker_tracker.vision.camera import Camera

NS_PER_S = 1_000_000_000
#: Queue depth of /awalker/posterior at the tracker and at its readers (reliable). The automatic start
#: publishes its window's posteriors at once (autostart's fit_window_s, 1.3 s: 41 at 30 Hz, 80 at 60 Hz);
#: with depth 10 the pose publisher lost the first 15 frames of a hands-off track, and `awalker track` then
#: waited its 10 s for their joint states (15.1 s for a 90-frame real walk, against 5.9 s at depth 200).
POSTERIOR_DEPTH = 200


def stamp_to_ns(stamp: Time) -> int:
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def ns_to_stamp(stamp_ns: int) -> Time:
    return Time(sec=int(stamp_ns // NS_PER_S), nanosec=int(stamp_ns % NS_PER_S))


def header(stamp_ns: int, frame_id: str) -> Header:
    return Header(stamp=ns_to_stamp(stamp_ns), frame_id=frame_id)


def points_to_msg(points: np.ndarray) -> list[Point]:
    return [Point(x=x, y=y, z=z) for x, y, z in np.asarray(points, float).reshape(-1, 3).tolist()]


def points_from_msg(points: list[Point]) -> np.ndarray:
    return np.array([[p.x, p.y, p.z] for p in points], float).reshape(-1, 3)


def body_pose_to_msg(hdr: Header, marker_names: tuple[str, ...], markers: np.ndarray,
                     joint_names: tuple[str, ...] = (), joint_angles: np.ndarray | None = None,
                     torso_position: np.ndarray | None = None,
                     torso_orientation: np.ndarray | None = None) -> BodyPose:
    """awalker_msgs/BodyPose from markers (M, 3) m, joint angles (J,) rad, torso pose (xyz, xyzw)."""
    msg = BodyPose(header=hdr, marker_names=list(marker_names), markers=points_to_msg(markers),
                   joint_names=list(joint_names))
    if joint_angles is not None:
        msg.joint_angles = array.array("d", np.asarray(joint_angles, float).tobytes())
    pose = Pose()
    if torso_position is not None:
        pose.position.x, pose.position.y, pose.position.z = (float(v) for v in torso_position)
    if torso_orientation is not None:
        q = pose.orientation
        q.x, q.y, q.z, q.w = (float(v) for v in torso_orientation)
    msg.torso = pose
    return msg


def body_pose_from_msg(msg: BodyPose) -> tuple[tuple[str, ...], np.ndarray]:
    """(marker names, markers (M, 3))."""
    return tuple(msg.marker_names), points_from_msg(msg.markers)


def summary_to_msg(summary: core.PosteriorSummary, world_frame: str = "world") -> PosteriorSummary:
    """awalker_msgs/PosteriorSummary stamped with the image stamp, poses in ``world_frame``."""
    hdr = header(summary.stamp_ns, world_frame)
    msg = PosteriorSummary(header=hdr, frame_index=int(summary.frame_index))
    msg.map_pose = body_pose_to_msg(hdr, summary.marker_names, summary.map_markers, summary.joint_names,
                                    summary.map_joint_angles, summary.map_torso_position,
                                    summary.map_torso_orientation)
    msg.mean_pose = body_pose_to_msg(hdr, summary.marker_names, summary.mean_markers)
    walker = WalkerState(header=hdr, stance_leg=int(summary.map_stance_leg))
    for name, value in summary.map_walker.items():
        setattr(walker, name, float(value))
    msg.map_walker = walker
    msg.speed = float(summary.speed)
    msg.speed_std = float(summary.speed_std)
    msg.stance_left_probability = float(summary.stance_left_probability)
    msg.effective_sample_size = float(summary.effective_sample_size)
    msg.num_particles = int(summary.num_particles)
    msg.resampled = bool(summary.resampled)
    msg.reseeded_fallen = int(summary.reseeded_fallen)
    msg.reacquired = int(summary.reacquired)
    msg.person_still = bool(summary.person_still)
    msg.track_id = int(summary.track_id)
    msg.person_in_view = bool(summary.person_in_view)
    msg.cameras_in_view = list(summary.cameras_in_view)
    msg.legs_renamed = bool(summary.legs_renamed)
    msg.contacts = [FootContact(foot=int(c.foot), position=Point(**dict(zip("xyz", map(float, c.position)))),
                                probability=float(c.probability), heel_strike=bool(c.heel_strike))
                    for c in summary.contacts]
    # clouds as packed float arrays: one Point object per sample cost ~8 ms per frame to build and as much to read
    msg.clouds = [ParticleCloud(marker_name=c.marker_name,
                                positions=array.array("f", np.asarray(c.points, np.float32).tobytes()),
                                weights=array.array("f", np.asarray(c.weights, np.float32).tobytes()))
                  for c in summary.clouds]
    msg.steps = [step_to_msg(step, world_frame) for step in summary.steps]
    return msg


def step_to_msg(step: Step, world_frame: str = "world") -> GaitStep:
    """awalker_msgs/GaitStep of a step timed in s of the stamps' clock (``PosteriorSummary.steps``): stamped with its
    strike frame's image stamp, the heel in ``world_frame``."""
    return GaitStep(header=header(step.stamp_ns, world_frame), strike=ns_to_stamp(round(step.time_s * NS_PER_S)),
                    index=step.index, frame_index=step.frame,
                    foot=GaitStep.LEFT if step.foot == "left" else GaitStep.RIGHT,
                    position=Point(x=step.x, y=step.y, z=0.0), step_length=step.step_length_m,
                    step_width=step.step_width_m, step_time=step.step_time_s, stride_time=step.stride_time_s,
                    cadence=step.cadence_steps_min, speed=step.speed_m_s)


def step_from_msg(msg: GaitStep) -> Step:
    """The step of an awalker_msgs/GaitStep (inverse of ``step_to_msg``)."""
    return Step(int(msg.index), int(msg.frame_index), stamp_to_ns(msg.header.stamp), stamp_to_ns(msg.strike) / NS_PER_S,
                "left" if msg.foot == GaitStep.LEFT else "right", float(msg.position.x), float(msg.position.y),
                float(msg.step_length), float(msg.step_width), float(msg.step_time), float(msg.stride_time),
                float(msg.cadence), float(msg.speed))


def summary_from_msg(msg: PosteriorSummary) -> core.PosteriorSummary:
    """Core PosteriorSummary from the message (inverse of ``summary_to_msg``)."""
    names, map_markers = body_pose_from_msg(msg.map_pose)
    _, mean_markers = body_pose_from_msg(msg.mean_pose)
    torso = msg.map_pose.torso
    walker = msg.map_walker
    return core.PosteriorSummary(
        frame_index=int(msg.frame_index), stamp_ns=stamp_to_ns(msg.header.stamp), marker_names=names,
        joint_names=tuple(msg.map_pose.joint_names), map_markers=map_markers, mean_markers=mean_markers,
        map_joint_angles=np.asarray(msg.map_pose.joint_angles, float),
        map_torso_position=np.array([torso.position.x, torso.position.y, torso.position.z]),
        map_torso_orientation=np.array([torso.orientation.x, torso.orientation.y, torso.orientation.z,
                                        torso.orientation.w]),
        map_stance_leg=int(walker.stance_leg),
        map_walker={k: float(getattr(walker, k)) for k in core.WALKER_FIELDS},
        speed=float(msg.speed), speed_std=float(msg.speed_std),
        stance_left_probability=float(msg.stance_left_probability),
        effective_sample_size=float(msg.effective_sample_size), num_particles=int(msg.num_particles),
        resampled=bool(msg.resampled), reseeded_fallen=int(msg.reseeded_fallen), reacquired=int(msg.reacquired),
        person_still=bool(msg.person_still), track_id=int(msg.track_id), person_in_view=bool(msg.person_in_view),
        cameras_in_view=tuple(msg.cameras_in_view), legs_renamed=bool(msg.legs_renamed),
        contacts=tuple(core.FootContactEstimate(int(c.foot), np.array([c.position.x, c.position.y, c.position.z]),
                                                float(c.probability), bool(c.heel_strike)) for c in msg.contacts),
        clouds=tuple(core.MarkerCloud(c.marker_name, cloud_positions(c), np.asarray(c.weights, float))
                     for c in msg.clouds),
        steps=tuple(step_from_msg(m) for m in msg.steps))


def cloud_positions(cloud: ParticleCloud) -> np.ndarray:
    """(K, 3) sample positions (m) of an awalker_msgs/ParticleCloud."""
    return np.asarray(cloud.positions, float).reshape(-1, 3)


#: One sample of the published particle cloud (sensor_msgs/PointCloud2, little endian): position (m,
#: world frame), weight (normalised over the full particle set) and marker, the index of the sample's
#: cloud in the PosteriorSummary (which body marker it is a sample of).
PARTICLE_POINT = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("weight", "<f4"), ("marker", "<u4")])
_POINT_FIELD_TYPES = {"<f4": PointField.FLOAT32, "<u4": PointField.UINT32}


def particles_to_pointcloud2(hdr: Header, clouds: list[ParticleCloud], per_cloud: int) -> PointCloud2:
    """sensor_msgs/PointCloud2 of the ``per_cloud`` heaviest samples of each awalker_msgs/ParticleCloud,
    fields as ``PARTICLE_POINT``: one packed buffer (a geometry_msgs/Point per sample in a MarkerArray
    cost the pose publisher ~4 ms a frame for 300 samples)."""
    parts = []
    for index, cloud in enumerate(clouds):
        weights = np.asarray(cloud.weights, np.float32)
        heaviest = np.argsort(-weights, kind="stable")[:max(int(per_cloud), 0)]
        part = np.empty(heaviest.size, PARTICLE_POINT)
        xyz = cloud_positions(cloud)[heaviest]
        part["x"], part["y"], part["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        part["weight"], part["marker"] = weights[heaviest], index
        parts.append(part)
    points = np.concatenate(parts) if parts else np.empty(0, PARTICLE_POINT)
    fields = [PointField(name=name, offset=int(offset), datatype=_POINT_FIELD_TYPES[dtype.str], count=1)
              for name, (dtype, offset) in PARTICLE_POINT.fields.items()]
    return PointCloud2(header=hdr, height=1, width=int(points.size), fields=fields, is_bigendian=False,
                       point_step=PARTICLE_POINT.itemsize, row_step=PARTICLE_POINT.itemsize * int(points.size),
                       data=array.array("B", points.tobytes()), is_dense=True)


def camera_from_msgs(name: str, info: CameraInfo, pose_stamped: PoseStamped) -> Camera:
    """A validated Camera (``vision.camera.camera_from_info``) from /<name>/camera_info and /<name>/camera_pose
    (the optical frame's pose in the world); InputError naming the topic on bad values."""
    from awalker_tracker.vision.camera import camera_from_info      # numba: only the nodes that need cameras

    p, q = pose_stamped.pose.position, pose_stamped.pose.orientation
    return camera_from_info(name, info, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w), f"/{name}/camera_info",
                            f"/{name}/camera_pose")
