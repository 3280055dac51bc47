"""Pose publisher node: posterior summaries -> JointState, MarkerArray (and tf when available).

Subscribes ``/awalker/posterior`` (awalker_msgs/PosteriorSummary) and publishes, stamped with
the image stamp of each summary:
- ``/awalker/joint_states`` and ``/humans/bodies/<body_id>/joint_states`` (REP 155 style),
  sensor_msgs/JointState with the MAP pose's joint names and angles;
- ``/awalker/markers`` visualization_msgs/MarkerArray in the world frame: skeleton lines and
  joints of the MAP pose, body cylinders (sizes from the body description), foot contacts (heel
  strikes larger; the contact of a foot that has lifted is sent as a DELETE);
- ``/awalker/particles`` sensor_msgs/PointCloud2 in the world frame: the heaviest samples of the
  posterior's head/pelvis/knee/ankle clouds, fields x, y, z, weight, marker (``messages.PARTICLE_POINT``);
- ``/awalker/gait_steps`` awalker_msgs/GaitStep for every heel strike the tracker's summaries carry
  (``PosteriorSummary.steps``: the MAP lineage's strikes once it has carried them ``TrackerConfig.step_lag_s``,
  ``inference.gait_events.LineageSteps``; of frames with the person in view; counted anew for each track): where
  the heel came down, step length and width, step and stride time, cadence and speed; the steps gait.csv has;
- tf ``world -> <body_id>_pelvis`` when ``tf2_ros`` can be imported (not on PyPI; optional).
"""
from __future__ import annotations

import numpy as np
import rclpy
from awalker_msgs.msg import FootContact, GaitStep, PosteriorSummary
from geometry_msgs.msg import Point, Vector3
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState, PointCloud2
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from awalker_tracker.model.body import SKELETON_EDGES, BodyDescription
from awalker_tracker.nodes.base import AwalkerNode, NodeParameter, declare_parameters
from awalker_tracker.nodes.messages import (
    POSTERIOR_DEPTH, particles_to_pointcloud2, points_from_msg)
from awalker_tracker.nodes.spin import run_node

#: Samples per body marker's cloud in /awalker/particles (the heaviest; the posterior message carries 200).
DEFAULT_CLOUD_POINTS = 50
#: A foot whose posterior probability of standing is below this has lifted: its contact marker is deleted.
CONTACT_MIN_PROBABILITY = 0.1


def body_cylinders(body: BodyDescription) -> tuple[tuple[str, str, float], ...]:
    """(start marker, end marker, radius m) of the cylinders drawn for the MAP body."""
    def r(*pairs):
        return float(np.mean(pairs))
    legs = []
    for side in ("left", "right"):
        legs += [(f"{side}_hip", f"{side}_knee", r(body.upper_leg_radii_top, body.upper_leg_radii_bottom)),
                 (f"{side}_knee", f"{side}_ankle", r(body.lower_leg_radii_top, body.lower_leg_radii_bottom)),
                 (f"{side}_heel", f"{side}_toe", r(body.foot_radii_heel, body.foot_radii_toe))]
    return (("pelvis", "thorax", r(body.torso_radii_bottom, body.torso_radii_top)),
            ("thorax", "head", r(body.head_radii_bottom, body.head_radii_top)), *legs)


def quaternion_z_to(direction: np.ndarray) -> tuple[float, float, float, float]:
    """Shortest rotation (x, y, z, w) taking the z axis onto ``direction``."""
    d = np.asarray(direction, float)
    d = d / max(np.linalg.norm(d), 1e-12)
    w = 1.0 + d[2]
    if w < 1e-9:                     # opposite: half turn about x
        return (1.0, 0.0, 0.0, 0.0)
    q = np.array([-d[1], d[0], 0.0, w])
    q /= np.linalg.norm(q)
    return tuple(float(v) for v in q)


def contact_on_ground(contact: FootContact) -> bool:
    """Whether a posterior's foot contact is shown: a finite position and at least ``CONTACT_MIN_PROBABILITY``."""
    return bool(np.isfinite(contact.position.x) and contact.probability >= CONTACT_MIN_PROBABILITY)


def joint_state_from_summary(msg: PosteriorSummary) -> JointState:
    return JointState(header=msg.header, name=list(msg.map_pose.joint_names),
                      position=list(msg.map_pose.joint_angles))


class MarkerBuilder:
    """The MarkerArray of posterior summaries' MAP poses and foot contacts (ids stable per namespace, so each
    frame replaces the last). Its Marker and Point messages are made once and updated for each summary:
    making them anew took ~1.2 ms of Python a frame on the pose publisher's thread (the messages are the
    same; ``publish`` serialises them at once, so reusing them is safe). The particle clouds go out as a
    PointCloud2 (``particles_to_pointcloud2``)."""

    def __init__(self, cylinders: tuple[tuple[str, str, float], ...], body_id: str = "walker") -> None:
        self.cylinders = cylinders
        self.body_id = body_id
        self._names: tuple[str, ...] | None = None      # the marker names the skeleton was laid out for
        self._lines = self._marker("skeleton", 0, Marker.LINE_LIST, (1.0, 0.5, 0.0, 1.0), (0.015, 0, 0))
        self._joints = self._marker("joints", 0, Marker.SPHERE_LIST, (1.0, 1.0, 0.0, 1.0), (0.04, 0.04, 0.04))
        self._line_rows: list[int] = []                 # marker row of each skeleton line end
        self._cylinders: list[tuple[Marker, int, int]] = []     # (marker, start row, end row)
        self._contacts: dict[int, Marker] = {}
        self._lifted: dict[int, Marker] = {}            # the DELETE of each contact marker

    def _marker(self, ns: str, mid: int, kind: int, rgba, scale) -> Marker:
        m = Marker(ns=f"{self.body_id}/{ns}", id=mid, type=kind, action=Marker.ADD)
        m.pose.orientation.w = 1.0
        m.scale = Vector3(x=float(scale[0]), y=float(scale[1]), z=float(scale[2]))
        m.color = ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
        return m

    def _lay_out(self, names: tuple[str, ...]) -> None:
        """The skeleton's lines and the cylinders for these marker names (those whose ends are all present)."""
        index = {n: i for i, n in enumerate(names)}
        self._line_rows = [index[end] for bone in SKELETON_EDGES if bone[0] in index and bone[1] in index for end in bone]
        self._lines.points = [Point() for _ in self._line_rows]
        self._joints.points = [Point() for _ in names]
        self._cylinders = []
        for i, (a, b, radius) in enumerate(self.cylinders):
            if a in index and b in index:
                cyl = self._marker("body", i, Marker.CYLINDER, (0.6, 0.6, 0.9, 0.5), (2 * radius, 2 * radius, 1e-3))
                self._cylinders.append((cyl, index[a], index[b]))
        self._names = names

    def build(self, msg: PosteriorSummary) -> MarkerArray:
        """The MarkerArray of ``msg``'s MAP pose: skeleton lines, joints, body cylinders, foot contacts."""
        hdr = msg.header
        names = tuple(msg.map_pose.marker_names)
        if names != self._names:
            self._lay_out(names)
        xyz = points_from_msg(msg.map_pose.markers)
        values = xyz.tolist()
        for point, row in zip(self._lines.points, self._line_rows):
            point.x, point.y, point.z = values[row]
        for point, value in zip(self._joints.points, values):
            point.x, point.y, point.z = value
        out: list[Marker] = [self._lines, self._joints]
        for cyl, a, b in self._cylinders:
            start, end = xyz[a], xyz[b]
            cyl.scale.z = max(float(np.linalg.norm(end - start)), 1e-3)
            mid = 0.5 * (start + end)
            position, orientation = cyl.pose.position, cyl.pose.orientation
            position.x, position.y, position.z = float(mid[0]), float(mid[1]), float(mid[2])
            orientation.x, orientation.y, orientation.z, orientation.w = quaternion_z_to(end - start)
            out.append(cyl)
        for i, contact in enumerate(msg.contacts):
            if not contact_on_ground(contact):
                # the foot has lifted: its marker goes (sent every frame, so a late subscriber drops it too)
                gone = self._lifted.get(i)
                if gone is None:
                    gone = self._lifted[i] = Marker(ns=f"{self.body_id}/contacts", id=i, action=Marker.DELETE)
                out.append(gone)
                continue
            dot = self._contacts.get(i)
            if dot is None:
                dot = self._contacts[i] = self._marker("contacts", i, Marker.SPHERE, (0.0, 0.0, 0.0, 0.0), (0, 0, 0.01))
            size = 0.08 if contact.heel_strike else 0.05
            dot.scale.x = dot.scale.y = size
            dot.color.r, dot.color.g, dot.color.b = (1.0, 0.1, 0.1) if contact.heel_strike else (0.1, 0.8, 0.8)
            dot.color.a = max(0.1, float(contact.probability))
            dot.pose.position = contact.position
            out.append(dot)
        for m in out:
            m.header = hdr
        return MarkerArray(markers=out)


#: The node's ROS parameters (declared from here; listed by ``awalker_pose_publisher --help``).
PARAMETERS = (
    NodeParameter("posterior_topic", "/awalker/posterior", "awalker_msgs/PosteriorSummary input topic"),
    NodeParameter("body_id", "walker", "REP 155 body id: /humans/bodies/<id>/..."),
    NodeParameter("body_description", "", "body YAML (segment sizes, m) for the cylinders; empty = default"),
    NodeParameter("publish_clouds", True, "publish the posterior particle clouds on /awalker/particles"),
    NodeParameter("cloud_points", DEFAULT_CLOUD_POINTS,
                  "samples per body marker's cloud on /awalker/particles (the heaviest)"),
)


class PosePublisherNode(AwalkerNode):
    """Publishes JointState / MarkerArray (and tf) for every posterior summary."""

    def __init__(self, **kwargs) -> None:
        super().__init__("awalker_pose_publisher", **kwargs)
        values = declare_parameters(self, PARAMETERS)
        body_id = values["body_id"]
        body_path = values["body_description"]
        self.body_id = body_id
        self.markers = MarkerBuilder(
            body_cylinders(BodyDescription.from_yaml(body_path) if body_path else BodyDescription.default()), body_id)
        self.publish_clouds = bool(values["publish_clouds"])
        self.cloud_points = int(values["cloud_points"])
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.joint_pub = self.create_publisher(JointState, "/awalker/joint_states", qos)
        self.rep155_pub = self.create_publisher(JointState, f"/humans/bodies/{body_id}/joint_states", qos)
        self.marker_pub = self.create_publisher(MarkerArray, "/awalker/markers", qos)
        self.particles_pub = self.create_publisher(PointCloud2, "/awalker/particles", qos)
        self.gait_pub = self.create_publisher(GaitStep, "/awalker/gait_steps", qos)
        self.tf_broadcaster = _tf_broadcaster(self)
        self.count = 0
        self.create_subscription(PosteriorSummary, values["posterior_topic"], self.on_summary,
                                 QoSProfile(depth=POSTERIOR_DEPTH, reliability=ReliabilityPolicy.RELIABLE))

    def set_body(self, body: BodyDescription) -> None:
        self.markers = MarkerBuilder(body_cylinders(body), self.body_id)

    def on_summary(self, msg: PosteriorSummary) -> None:
        joints = joint_state_from_summary(msg)
        self.joint_pub.publish(joints)
        self.rep155_pub.publish(joints)
        self.marker_pub.publish(self.markers.build(msg))
        if self.publish_clouds:
            self.particles_pub.publish(particles_to_pointcloud2(msg.header, msg.clouds, self.cloud_points))
        for step in msg.steps:
            self.gait_pub.publish(step)
        if self.tf_broadcaster is not None:
            from geometry_msgs.msg import TransformStamped

            t = TransformStamped(header=msg.header, child_frame_id=f"{self.body_id}_pelvis")
            p, q = msg.map_pose.torso.position, msg.map_pose.torso.orientation
            t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = p.x, p.y, p.z
            t.transform.rotation = q
            self.tf_broadcaster.sendTransform(t)
        self.count += 1


def _tf_broadcaster(node: Node):
    try:
        from tf2_ros import TransformBroadcaster
    except ImportError:
        return None
    return TransformBroadcaster(node)


def main(args: list[str] | None = None) -> int:
    """Console script ``awalker_pose_publisher``; exit status 2 on bad parameters."""
    return run_node("awalker_pose_publisher", PosePublisherNode, args, parameters=PARAMETERS,
                    summary="Posterior summaries -> joint states, RViz markers, particle clouds and gait steps.")

