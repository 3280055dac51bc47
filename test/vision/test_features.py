"""The feature extractor: the flow on its worker thread gives the features of the flow computed in turn."""
from __future__ import annotations

import os
import select
import signal
import threading

import numpy as np
import pytest

from awalker_tracker.vision import flow as flow_module
from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor, map_downsample
from vision_scene import background_image, noisy, render_frames, side_camera, walking_poses

CAM = side_camera()
ESTIMATE = flow_module.GridFlow.estimate


def _frames() -> list[np.ndarray]:
    """Three background-only frames, then a walker: learning frames, the first flow and moving flow."""
    rng = np.random.default_rng(7)
    clean = background_image(CAM)
    walking, _ = render_frames(CAM, walking_poses(5), clean)
    return [noisy(clean, rng) for _ in range(3)] + list(walking)


def _extract(frames: list[np.ndarray], threads: str, monkeypatch) -> tuple[list, set[str]]:
    """Features of ``frames`` with ``AWALKER_THREADS=threads``, and the names of the threads that ran the flow."""
    monkeypatch.setenv("AWALKER_THREADS", threads)
    ran_on: set[str] = set()

    def recorded(self, prev_grey, grey):
        ran_on.add(threading.current_thread().name)
        return ESTIMATE(self, prev_grey, grey)

    monkeypatch.setattr(flow_module.GridFlow, "estimate", recorded)
    extractor = FeatureExtractor(FeatureConfig(background_frames=3, downsample=2))
    return [extractor.process(f) for f in frames], ran_on


@pytest.mark.parametrize("threads", ["2", "3"])
def test_flow_on_its_thread_gives_the_features_of_one_thread(monkeypatch, threads: str):
    frames = _frames()
    alone, alone_on = _extract(frames, "1", monkeypatch)
    both, both_on = _extract(frames, threads, monkeypatch)
    assert alone_on == {threading.current_thread().name}
    assert both_on and all(name.startswith("awalker-flow") for name in both_on)
    assert not alone[0].flow.valid.any() and alone[-1].flow.valid.any() and alone[-1].llr.any()
    for one, other in zip(alone, both):
        np.testing.assert_array_equal(one.llr, other.llr)
        for field in ("centers", "flow", "covariance", "valid"):
            np.testing.assert_array_equal(getattr(one.flow, field), getattr(other.flow, field))


def test_a_frame_of_another_size_is_refused_and_the_flow_thread_is_waited_for(monkeypatch):
    monkeypatch.setenv("AWALKER_THREADS", "2")
    frames = _frames()
    extractor = FeatureExtractor(FeatureConfig(background_frames=3, downsample=2))
    for frame in frames[:5]:
        extractor.process(frame)
    with pytest.raises(ValueError, match="differs from the first frames'"):
        extractor.process(frames[5][:-16])
    after = extractor.process(frames[5])         # the extractor still works, its flow from frame 4
    assert after.flow.valid.any() and extractor.frame_index == 6


def test_submitted_frames_are_done_in_order_with_the_features_of_process(monkeypatch):
    """submit returns once the maps are made; the futures complete in the frames' order with process's features,
    and a frame waits while two others wait for their flow."""
    frames = _frames()
    alone, _ = _extract(frames, "1", monkeypatch)
    monkeypatch.setenv("AWALKER_THREADS", "2")
    release = threading.Event()

    def held(self, prev_grey, grey):
        assert release.wait(30.0)
        return ESTIMATE(self, prev_grey, grey)

    monkeypatch.setattr(flow_module.GridFlow, "estimate", held)
    extractor = FeatureExtractor(FeatureConfig(background_frames=3, downsample=2))
    done_order: list[int] = []
    futures = []

    def submit(k: int) -> None:
        futures.append(extractor.submit(frames[k]))
        futures[-1].add_done_callback(lambda _, k=k: done_order.append(k))

    for k in range(3):          # frame 0 has no flow to wait for; frames 1 and 2 wait
        submit(k)
    blocked = threading.Thread(target=submit, args=(3,))
    blocked.start()
    blocked.join(0.5)
    assert blocked.is_alive() and len(futures) == 3 and done_order == [0]     # held: two frames wait already
    release.set()
    blocked.join(30.0)
    for k in range(4, len(frames)):
        submit(k)
    features = [future.result(30.0) for future in futures]
    extractor.close()
    assert done_order == list(range(len(frames)))
    for one, other in zip(alone, features):
        np.testing.assert_array_equal(one.llr, other.llr)
        for field in ("centers", "flow", "covariance", "valid"):
            np.testing.assert_array_equal(getattr(one.flow, field), getattr(other.flow, field))


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_a_forked_child_starts_its_own_flow_thread(monkeypatch):
    monkeypatch.setenv("AWALKER_THREADS", "2")
    frames = _frames()
    extractor = FeatureExtractor(FeatureConfig(background_frames=3, downsample=2))
    for frame in frames[:4]:
        extractor.process(frame)               # the parent's flow thread exists
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:                                # child: without a thread of its own this would hang
        try:
            ok = extractor.process(frames[4]).flow.valid.any()
            os.write(write, b"1" if ok else b"0")
        finally:
            os._exit(0)
    os.close(write)
    answered, _, _ = select.select([read], [], [], 30.0)
    if not answered:                            # hung on the parent's thread, which the child lacks
        os.kill(pid, signal.SIGKILL)
    _, status = os.waitpid(pid, 0)
    assert answered and os.read(read, 1) == b"1" and status == 0


def test_map_downsample_keeps_one_camera_coarse_and_makes_several_about_160_pixels_wide():
    """One camera keeps FeatureConfig's 4 at any size; two cameras or more get maps ~160 map pixels wide:
    2 at 320x240, 4 at 640x480, 8 at 1280x960, and at least 1 on tiny images."""
    assert FeatureConfig().downsample == 4
    assert [map_downsample(w, 1) for w in (160, 320, 640, 1280)] == [4, 4, 4, 4]
    assert [map_downsample(w, 2) for w in (100, 320, 640, 1280)] == [1, 2, 4, 8]
    assert map_downsample(320, 3) == 2
    for width, cameras in ((0, 2), (320, 0)):
        with pytest.raises(ValueError, match="must be >= 1"):
            map_downsample(width, cameras)
