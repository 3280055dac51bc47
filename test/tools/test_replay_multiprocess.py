"""`awalker replay` in a separate process feeding a subscriber here, in lockstep and in rate mode."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from rclpy.executors import SingleThreadedExecutor

from replay_helpers import CAMERAS, Receiver, make_bag


@pytest.mark.parametrize("mode", ["lockstep", "rate"])
def test_replay_across_processes(localhost_context, tmp_path: Path, mode: str) -> None:
    bag = tmp_path / "bag"
    stamps, images = make_bag(bag, frames=6)
    receiver = Receiver(ack=mode == "lockstep", context=localhost_context)
    executor = SingleThreadedExecutor(context=localhost_context)
    executor.add_node(receiver)
    args = [sys.executable, "-m", "awalker_tools.cli", "replay", str(bag), "--wait-for-subscribers", "20"]
    args += ["--lockstep", "--ack-timeout", "20"] if mode == "lockstep" else ["--rate", "3"]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ))
    try:
        deadline = time.monotonic() + 60
        while proc.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.02)
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.02)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        executor.shutdown()
        receiver.destroy_node()
    assert proc.returncode == 0, out + err
    assert "complete; 6 frames" in out
    if mode == "lockstep":
        assert "6 acks" in out
    for cam in CAMERAS:
        assert [s for s, _ in receiver.images[cam]] == stamps
        assert [b for _, b in receiver.images[cam]] == [f[cam].tobytes() for f in images]
