"""Features node throughput at 640x480: (1) the per-frame stages in one loop (Image message ->
RGB, appearance maps, grid flow, ImageFeatures message) with the time per stage; (2) the real
FeatureNode in an rclpy executor, fed Image messages one at a time (next image when the
previous frame's features arrive: DDS, callbacks and (de)serialisation included); (2b) the same node
spinning in a thread of its own, fed by a camera stand-in that keeps two images ahead of the features it got
back (what the node sustains when the camera does not wait for it; the round trip's hand-offs overlap); (3) the
flow's median endpoint error on the walker against the rendered motion. Prints JSON.

    .venv/bin/python benchmarks/bench_features.py [--frames 90] [--opencv-threads 1]

Frames are a rendered walker over a textured background (rendered once, cycled).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test" / "vision"))
from vision_scene import BODY, background_image, noisy, render_frames, side_camera, walking_poses  # noqa: E402

from awalker_tracker.nodes.features_node import features_to_msg  # noqa: E402
from awalker_tracker.nodes.messages import header  # noqa: E402
from awalker_tracker.vision.background import measurements  # noqa: E402
from awalker_tracker.vision.decode import decode_image  # noqa: E402
from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor  # noqa: E402
from awalker_tracker.vision.flow import GridFlow, to_grey  # noqa: E402
from awalker_tracker.vision.render import render  # noqa: E402


def image_msg(rgb: np.ndarray, stamp: int):
    from sensor_msgs.msg import Image

    msg = Image(header=header(stamp, "cam_optical_frame"), height=rgb.shape[0], width=rgb.shape[1],
                encoding="rgb8", step=rgb.shape[1] * 3)
    msg.data = rgb.tobytes()
    return msg


def flow_endpoint_error(cam, poses, frames) -> dict:
    """Median EPE (px) over 16 px cells >= 70 % covered by the body, frames 1 -> 2 ... 4 -> 5."""
    errors, speeds = [], []
    flow = GridFlow()
    for a in range(1, len(poses) - 1):
        seg_a, seg_b = poses[a].segments(), poses[a + 1].segments()
        result = render(BODY, seg_a, cam)
        v, u = np.nonzero(result.labels >= 0)
        part, local = result.labels[v, u], result.local[v, u]
        world = [s.origin[0][part] + np.einsum("kij,kj->ki", s.rotation[0][part], local) for s in (seg_a, seg_b)]
        motion = cam.project(world[1])[0] - cam.project(world[0])[0]
        grid = flow.estimate(to_grey(frames[a]), to_grey(frames[a + 1]))
        cell = (v // 16) * grid.shape[1] + (u // 16)
        counts = np.bincount(cell, minlength=grid.shape[0] * grid.shape[1])
        summed = np.stack([np.bincount(cell, motion[:, i], minlength=counts.size) for i in range(2)], -1)
        covered = np.flatnonzero(counts >= 0.7 * 256)
        truth = summed[covered] / counts[covered, None]
        errors.append(np.linalg.norm(grid.flow.reshape(-1, 2)[covered] - truth, axis=1))
        speeds.append(np.linalg.norm(truth, axis=1))
    errors, speeds = np.concatenate(errors), np.concatenate(speeds)
    return {"cells": int(errors.size), "median_epe_px": float(np.median(errors)),
            "p90_epe_px": float(np.percentile(errors, 90)), "median_true_motion_px": float(np.median(speeds))}


def _node_and_camera(domain_id: int, depth: int):
    """A FeatureNode for camera "cam" (5 background-only frames) and a stand-in node publishing its images and
    taking its features, in a private context: (context, node, probe, image publisher, received features)."""
    import rclpy
    from awalker_msgs.msg import ImageFeatures
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import Image

    from awalker_tracker.nodes.features_node import FeatureNode

    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    node = FeatureNode(context=context, parameter_overrides=[Parameter("camera_name", value="cam"),
                                                             Parameter("background_frames", value=5)])
    probe = Node("bench_probe", context=context)
    received: list = []
    probe.create_subscription(ImageFeatures, "/cam/features", received.append, QoSProfile(depth=depth))
    return context, node, probe, probe.create_publisher(Image, "/cam/image_raw", QoSProfile(depth=depth)), received


def _matched(executor, probe, pub) -> None:
    """Spin until the image and features topics have matched both ways (10 s at most)."""
    deadline = time.monotonic() + 10
    while (pub.get_subscription_count() == 0 or probe.count_publishers("/cam/features") == 0) \
            and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)


def _publish(pub, msgs: list, k: int) -> None:
    """Image k of the cycle ``msgs``, stamped at 30 Hz."""
    msg = msgs[k % len(msgs)]
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1 + k // 30, (k % 30) * 33_333_333
    pub.publish(msg)


def node_throughput(msgs: list, frames: int) -> dict:
    """Frames/s of FeatureNode in a private context, one image in flight at a time."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    context, node, probe, pub, received = _node_and_camera(97, 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(probe)
    try:
        _matched(executor, probe, pub)
        deadline = time.monotonic() + 70
        started = None
        for k in range(frames + 5):
            if k == 5:
                started = time.perf_counter()
            _publish(pub, msgs, k)
            while len(received) < k + 1 and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.1)
        elapsed = time.perf_counter() - started
        return {"frames": frames, "frames_per_s": frames / elapsed, "received": len(received) - 5,
                "ms_in_image_callback": 1e3 * node.stats.seconds / max(node.stats.frames, 1)}
    finally:
        executor.shutdown()
        node.destroy_node()
        probe.destroy_node()
        rclpy.try_shutdown(context=context)


def node_streaming(msgs: list, frames: int, in_flight: int = 2) -> dict:
    """Frames/s of FeatureNode spinning in a thread of its own (as a node in its own process would), fed by a
    camera stand-in in this thread that keeps ``in_flight`` images published ahead of the features it has
    received (a camera does not wait for the node): what the node sustains, apart from the round trip."""
    import threading

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    context, node, probe, pub, received = _node_and_camera(98, frames + 10)
    node_executor, probe_executor = SingleThreadedExecutor(context=context), SingleThreadedExecutor(context=context)
    node_executor.add_node(node)
    probe_executor.add_node(probe)
    spinner = threading.Thread(target=node_executor.spin, daemon=True)
    spinner.start()
    try:
        _matched(probe_executor, probe, pub)
        total, warm = frames + 5, 5        # the first 5 (background-only) one at a time, as above
        sent, started = 0, None
        deadline = time.monotonic() + 120
        while len(received) < total and time.monotonic() < deadline:
            while sent < total and sent < len(received) + (1 if sent < warm else in_flight):
                _publish(pub, msgs, sent)
                sent += 1
            probe_executor.spin_once(timeout_sec=0.1)
            if started is None and len(received) >= warm:
                started = time.perf_counter()
        elapsed = time.perf_counter() - started
        return {"frames": len(received) - warm, "in_flight": in_flight,
                "frames_per_s": (len(received) - warm) / elapsed,
                "ms_in_image_callback": 1e3 * node.stats.seconds / max(node.stats.frames, 1)}
    finally:
        node_executor.shutdown()
        probe_executor.shutdown()
        spinner.join(timeout=5)
        node.destroy_node()
        probe.destroy_node()
        rclpy.try_shutdown(context=context)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=90)
    parser.add_argument("--opencv-threads", type=int, default=1, help="cv2.setNumThreads (0 = OpenCV default)")
    args = parser.parse_args()
    if args.opencv_threads > 0:
        import cv2

        cv2.setNumThreads(args.opencv_threads)
    cam = side_camera(640, 480, 600.0)
    bg = background_image(cam)
    rng = np.random.default_rng(0)
    poses = walking_poses(8)
    print("rendering frames ...", file=sys.stderr, flush=True)
    frames, _ = render_frames(cam, poses, bg)
    cycle = frames + frames[::-1]
    msgs = [image_msg(f, k) for k, f in enumerate(cycle)]
    background_msgs = [image_msg(noisy(bg, rng), k) for k in range(5)]
    config = FeatureConfig(background_frames=5)
    extractor = FeatureExtractor(config)
    for _ in range(5):
        extractor.process(noisy(bg, rng))
    stages = {"decode": 0.0, "extract": 0.0, "to_msg": 0.0}
    started, cpu_started = time.perf_counter(), time.process_time()
    for k in range(args.frames):
        t0 = time.perf_counter()
        rgb = decode_image(msgs[k % len(msgs)], "/cam/image_raw")
        t1 = time.perf_counter()
        feats = extractor.process(rgb)
        t2 = time.perf_counter()
        features_to_msg(feats, header(k, "cam_optical_frame"), "cam")
        t3 = time.perf_counter()
        stages["decode"] += t1 - t0
        stages["extract"] += t2 - t1
        stages["to_msg"] += t3 - t2
        if k % 30 == 29:
            print(f"{k + 1}/{args.frames} frames", file=sys.stderr, flush=True)
    total = time.perf_counter() - started
    cpu = time.process_time() - cpu_started
    # Split of the extract stage: appearance maps vs flow.
    t0 = time.perf_counter()
    for f in frames:
        m = measurements(f, config.downsample)
        extractor.foreground.log_likelihood_ratios(m, extractor.background, config.llr_clip, config.outlier_probability)
    appearance = (time.perf_counter() - t0) / len(frames)
    flow = GridFlow(config.flow)
    greys = [to_grey(f) for f in frames]
    t0 = time.perf_counter()
    for a, b in zip(greys[:-1], greys[1:]):
        flow.estimate(a, b)
    flow_ms = (time.perf_counter() - t0) / (len(greys) - 1)
    print(json.dumps({
        "benchmark": "features", "width": 640, "height": 480, "frames": args.frames,
        "opencv_threads": args.opencv_threads,
        "load_average_1min": os.getloadavg()[0], "cpus": os.cpu_count(),
        "downsample": config.downsample, "flow_cell_size": config.flow.cell_size, "flow_scale": config.flow.scale,
        "frames_per_s": args.frames / total,
        "cpu_ms_per_frame": 1e3 * cpu / args.frames,
        "ms_per_frame": {k: 1e3 * v / args.frames for k, v in stages.items()},
        "extract_split_ms": {"appearance_maps": 1e3 * appearance, "grid_flow": 1e3 * flow_ms},
        "node_in_executor": node_throughput(background_msgs + msgs, args.frames),
        "node_streaming": node_streaming(background_msgs + msgs, args.frames),
        "flow_accuracy": flow_endpoint_error(cam, poses, frames),
    }, indent=2))


if __name__ == "__main__":
    main()
