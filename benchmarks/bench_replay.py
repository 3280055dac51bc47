"""Replay throughput (frames/s) and latency (publish -> subscriber callback, ms) for 640x480 rgb8
images, in one process (one executor) and across two processes (Fast DDS, default transport and
a 16 MB shared-memory segment). Lockstep: the receiver acks each frame; rate mode: a 30 Hz bag
at real time and as fast as possible (rate 1000), counting lost frames. Prints JSON.

    .venv/bin/python benchmarks/bench_replay.py [--frames 120] [--domain 77]

Latency uses CLOCK_MONOTONIC, shared by the processes of one host.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

WIDTH, HEIGHT = 640, 480
BAG_PERIOD_NS = 33_333_333  # 30 Hz
SHM_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor>
      <transport_id>shm_16mb</transport_id>
      <type>SHM</type>
      <segment_size>16777216</segment_size>
    </transport_descriptor>
    <transport_descriptor>
      <transport_id>udp</transport_id>
      <type>UDPv4</type>
    </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="awalker_shm_16mb" is_default_profile="true">
    <rtps>
      <userTransports>
        <transport_id>shm_16mb</transport_id>
        <transport_id>udp</transport_id>
      </userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
    </rtps>
  </participant>
</profiles>
"""


def make_bag(path: Path, frames: int) -> None:
    from awalker_tools.bagio import SequenceWriter
    from awalker_tracker.vision.camera import Camera

    cam = Camera.look_at("cam0", WIDTH, HEIGHT, 500.0, [5.0, 0.0, 1.5], [0.0, 0.0, 1.0])
    rng = np.random.default_rng(0)
    pool = [rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8) for _ in range(4)]
    with SequenceWriter(path, [cam]) as writer:
        for i in range(frames):
            writer.write_frame(1_000_000_000 + i * BAG_PERIOD_NS, {"cam0": pool[i % len(pool)]})


def receiver_node(context, ack: bool, receive_times: dict[int, float]):
    """A node taking /cam0/image_raw (reliable, deep queue); records CLOCK_MONOTONIC per stamp; acks."""
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Image
    from std_msgs.msg import Header

    node = Node("bench_receiver", context=context)
    ack_pub = node.create_publisher(Header, "/awalker/ack", 10)

    def on_image(msg: Image) -> None:
        now = time.monotonic()
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        receive_times[stamp] = now
        if ack:
            ack_pub.publish(msg.header)

    qos = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(Image, "/cam0/image_raw", on_image, qos)
    return node


def new_context(domain: int):
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    return ctx


def stats(frames: int, duration: float, publish: dict[int, float], receive: dict[int, float]) -> dict:
    lat = np.array([receive[s] - publish[s] for s in publish if s in receive]) * 1e3
    delivered_span = max(receive.values()) - min(publish.values()) if receive and publish else 0.0
    return {
        "frames_published": len(publish),
        "frames_received": len(receive),
        "lost": len(publish) - len([s for s in publish if s in receive]),
        "published_per_s": round(frames / duration, 1) if duration > 0 else None,
        # received frames over first publish -> last receive: what a consumer actually gets
        "delivered_per_s": round(len(receive) / delivered_span, 1) if delivered_span > 0 else None,
        "latency_ms": {
            "median": round(float(np.median(lat)), 3),
            "p95": round(float(np.percentile(lat, 95)), 3),
            "max": round(float(lat.max()), 3),
        } if lat.size else None,
    }


def run_replay(
    bag: Path, domain: int, lockstep: bool, rate: float, receive: dict[int, float] | None
) -> tuple[float, dict[int, float], object]:
    """Replay in this process; with ``receive`` given, the receiver runs in the same executor."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from awalker_tools.replay import ReplayConfig, Replayer, run_replay as drive

    ctx = new_context(domain)
    publish: dict[int, float] = {}
    try:
        executor = SingleThreadedExecutor(context=ctx)
        if receive is not None:
            executor.add_node(receiver_node(ctx, lockstep, receive))
        node = Node("bench_replay", context=ctx)
        executor.add_node(node)
        config = ReplayConfig(lockstep=lockstep, rate=rate, wait_for_subscribers=20.0, ack_timeout=20.0,
                              topics=("/cam0/image_raw",))
        replayer = Replayer(node, bag, config, on_frame=lambda stamp: publish.__setitem__(stamp, time.monotonic()))
        summary = drive(executor, replayer)
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.01)
        executor.shutdown()
    finally:
        ctx.try_shutdown()
    # Throughput over the publishing span only (not discovery, settle or the final flush).
    times = sorted(publish.values())
    span = times[-1] - times[0] if len(times) > 1 else 0.0
    return span * len(times) / max(len(times) - 1, 1), publish, summary


def receiver_process(domain: int, ack: bool, frames: int, timeout: float) -> None:
    """Child process: receive ``frames`` images (or stop 3 s after the last one, or at ``timeout``);
    print {stamp: time} JSON."""
    from rclpy.executors import SingleThreadedExecutor

    ctx = new_context(domain)
    receive: dict[int, float] = {}
    try:
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(receiver_node(ctx, ack, receive))
        print("ready", flush=True)
        end = time.monotonic() + timeout
        while len(receive) < frames and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
            if receive and time.monotonic() - max(receive.values()) > 3.0:
                break  # frames were lost; the replay is over
        executor.shutdown()
    finally:
        ctx.try_shutdown()
    print(json.dumps({str(k): v for k, v in receive.items()}), flush=True)


def cross_process(bag: Path, domain: int, lockstep: bool, rate: float, frames: int, env_extra: dict) -> dict:
    env = dict(os.environ, **env_extra)
    child = subprocess.Popen(
        [sys.executable, __file__, "--receiver", "--domain", str(domain), "--frames", str(frames),
         *(["--ack"] if lockstep else [])],
        stdout=subprocess.PIPE, text=True, env=env,
    )
    saved = {k: os.environ.get(k) for k in env_extra}
    os.environ.update(env_extra)
    try:
        assert child.stdout is not None and child.stdout.readline().strip() == "ready"
        duration, publish, summary = run_replay(bag, domain, lockstep, rate, None)
        out, _ = child.communicate(timeout=120)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        if child.poll() is None:
            child.kill()
    receive = {int(k): v for k, v in json.loads(out.strip().splitlines()[-1]).items()}
    return stats(len(publish), duration, publish, receive)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--domain", type=int, default=77)
    parser.add_argument("--receiver", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--ack", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.receiver:
        receiver_process(args.domain, args.ack, args.frames, timeout=120.0)
        return 0
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    results: dict = {"image": f"{WIDTH}x{HEIGHT} rgb8", "frames": args.frames, "bag_rate_hz": 30}
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "bench"
        make_bag(bag, args.frames)
        receive: dict[int, float] = {}
        duration, publish, _ = run_replay(bag, args.domain, True, 1.0, receive)
        results["in_process_lockstep"] = stats(len(publish), duration, publish, receive)
        print("in-process done", file=sys.stderr)
        with tempfile.NamedTemporaryFile("w", suffix=".xml", delete=False) as xml:
            xml.write(SHM_PROFILE)
        transports = {"default": {}, "shm_16mb": {"FASTRTPS_DEFAULT_PROFILES_FILE": xml.name}}
        try:
            for name, env in transports.items():
                results[f"two_process_lockstep_{name}"] = cross_process(bag, args.domain, True, 1.0, args.frames, env)
                results[f"two_process_rate1_{name}"] = cross_process(bag, args.domain, False, 1.0, args.frames, env)
                results[f"two_process_rate1000_{name}"] = cross_process(
                    bag, args.domain, False, 1000.0, args.frames, env)
                print(f"two-process {name} done", file=sys.stderr)
        finally:
            os.unlink(xml.name)
    print(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
