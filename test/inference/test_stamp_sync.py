"""Exact-stamp camera synchroniser."""
from __future__ import annotations

import numpy as np
import pytest

from awalker_tracker.inference.sync import StampSynchronizer


def test_pairs_interleaved_cameras_in_order():
    sync = StampSynchronizer(["left", "right", "top"])
    rng = np.random.default_rng(0)
    stamps = [100 * (k + 1) for k in range(20)]
    # each camera in order, but the cameras interleave randomly (one camera runs ahead)
    queues = {c: [(s, f"{c}{s}") for s in stamps] for c in sync.cameras}
    emitted, issues = [], []
    while any(queues.values()):
        cam = rng.choice([c for c in sync.cameras if queues[c]])
        stamp, item = queues[cam].pop(0)
        f, i = sync.add(cam, stamp, item)
        emitted += f
        issues += i
    assert issues == []
    assert [f.stamp_ns for f in emitted] == stamps
    assert all(f.items == (f"left{f.stamp_ns}", f"right{f.stamp_ns}", f"top{f.stamp_ns}") for f in emitted)
    assert sync.flush() == []


def test_missing_camera_is_reported_not_silently_dropped():
    sync = StampSynchronizer(["a", "b"])
    assert sync.add("a", 1, "a1") == ([], [])
    frames, issues = sync.add("a", 2, "a2")
    assert frames == [] and issues == []
    frames, issues = sync.add("b", 2, "b2")        # b never sent stamp 1
    assert [f.stamp_ns for f in frames] == [2]
    assert len(issues) == 1 and issues[0].kind == "incomplete" and issues[0].cameras == ("b",)
    assert "stamp 1 ns" in issues[0].message and "b" in issues[0].message
    sync.add("a", 3, "a3")
    end = sync.flush()
    assert [(i.kind, i.stamp_ns, i.cameras) for i in end] == [("incomplete", 3, ("b",))]


def test_out_of_order_duplicate_and_unknown_camera():
    sync = StampSynchronizer(["a", "b"])
    sync.add("a", 5, 0)
    assert sync.add("a", 4, 0)[1][0].kind == "out_of_order"
    assert sync.add("a", 5, 0)[1][0].kind == "duplicate"
    unknown = sync.add("c", 5, 0)[1][0]
    assert unknown.kind == "unknown_camera" and "'c'" in unknown.message
    frames, _ = sync.add("b", 5, 0)
    assert len(frames) == 1
    late = sync.add("b", 3, 0)[1][0]               # behind b's own last stamp
    assert late.kind == "out_of_order"
    sync2 = StampSynchronizer(["a", "b"])
    sync2.add("a", 5, 0)
    sync2.add("b", 5, 0)
    late2 = sync2.add("a", 5, 0)[1][0]
    assert late2.kind == "duplicate"


def test_bounded_queue_reports_overflow():
    sync = StampSynchronizer(["a", "b"], max_pending=3)
    issues = []
    for s in range(1, 6):
        issues += sync.add("a", s, s)[1]
    assert [(i.kind, i.stamp_ns) for i in issues] == [("overflow", 1), ("overflow", 2)]
    assert sync.pending_stamps == [3, 4, 5]


def test_single_camera_passes_through_and_bad_setup():
    sync = StampSynchronizer(["only"])
    assert [f.items for f in sync.add("only", 10, "x")[0]] == [("x",)]
    with pytest.raises(ValueError):
        StampSynchronizer([])
    with pytest.raises(ValueError):
        StampSynchronizer(["a", "a"])


def test_discard_gives_up_on_a_frame():
    sync = StampSynchronizer(["a", "b"])
    sync.add("a", 1, "a1")
    issue = sync.discard(1, "timed out")
    assert issue.kind == "incomplete" and issue.cameras == ("b",) and "timed out" in issue.message
    assert sync.discard(1) is None and sync.pending_stamps == []
    assert sync.add("b", 1, "b1")[1][0].kind == "out_of_order"      # too late now
