"""Pair per-camera messages into frames by nearest stamp (a small, tested replacement for message_filters).

Each camera delivers its items in increasing stamp order (cameras may interleave in any way). A frame is
the earliest waiting item and, from each other camera, its next item if that lies within ``tolerance`` of
a frame period after it (``tolerance`` 0: equal stamps only). A frame is emitted once every camera has
either an item in it or a later item outside it (it skipped the frame): a frame missing a camera is
emitted with ``None`` for that camera, not dropped, and reported. Frames come out in increasing stamp
order; a frame's stamp is that of its first camera (in the synchroniser's order) present. The frame
period is ``period_ns`` if given, else the smallest step seen between two items of one camera (until one
is seen, only equal stamps pair). Everything that is not paired is returned as a ``SyncIssue`` (late or
duplicate stamp, unknown camera, a frame some cameras did not deliver, queue overflow).
"""
from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

#: Frame periods by which the images of one frame may differ in stamp, by default: a third of a frame.
DEFAULT_TOLERANCE = 1.0 / 3.0


@dataclass(frozen=True)
class SyncedFrame:
    """Items of the cameras for one frame, in the synchroniser's camera order (None: the camera has none),
    and their stamps (ns)."""

    stamp_ns: int
    items: tuple[Any, ...]
    stamps: tuple[int | None, ...] = ()

    @property
    def last_stamp_ns(self) -> int:
        """The latest stamp of the frame's items (what a lockstep replay's acknowledgement carries)."""
        return max((s for s in self.stamps if s is not None), default=self.stamp_ns)


@dataclass(frozen=True)
class SyncIssue:
    """Something that could not be paired, with a message naming camera and stamp."""

    kind: str                      # out_of_order | duplicate | unknown_camera | incomplete | overflow
    stamp_ns: int
    cameras: tuple[str, ...]       # the offending camera, or the cameras missing from a frame
    message: str


class StampSynchronizer:
    """Nearest-stamp synchroniser for C cameras with at most ``max_pending`` items waiting per camera."""

    def __init__(self, cameras: Sequence[str], max_pending: int = 30, tolerance: float = 0.0,
                 period_ns: int | None = None) -> None:
        if not cameras:
            raise ValueError("StampSynchronizer needs at least one camera")
        if len(set(cameras)) != len(cameras):
            raise ValueError(f"camera names must be unique, got {list(cameras)}")
        if max_pending < 1:
            raise ValueError(f"max_pending must be >= 1, got {max_pending}")
        if not 0.0 <= tolerance < 1.0:
            raise ValueError(f"tolerance must lie in [0, 1) frame periods, got {tolerance}")
        if period_ns is not None and period_ns <= 0:
            raise ValueError(f"period_ns must be > 0, got {period_ns}")
        self.cameras = tuple(cameras)
        self.max_pending = int(max_pending)
        self.tolerance = float(tolerance)
        self.period_ns = period_ns
        self._given_period = period_ns is not None
        self._queues: dict[str, deque[tuple[int, Any]]] = {c: deque() for c in self.cameras}
        self._last_stamp: dict[str, int | None] = {c: None for c in self.cameras}   # last accepted per camera
        self._last_emitted: int | None = None     # the last emitted frame's earliest stamp + tolerance

    @property
    def pending_stamps(self) -> list[int]:
        """Stamps of the items waiting, oldest first."""
        return sorted(s for q in self._queues.values() for s, _ in q)

    def tolerance_ns(self) -> float | None:
        """How far after a frame's earliest item another camera's item may lie (ns); None until the period is
        known (with a tolerance above 0)."""
        if self.tolerance == 0.0:
            return 0.0
        return None if self.period_ns is None else self.tolerance * self.period_ns

    def _tolerance_whole_ns(self) -> int:
        """The tolerance in whole ns (0 until it is known), to add to stamps in integers: a stamp of ~1.7e18 ns
        as a float is rounded to 256 ns, and a frame's own earliest stamp then fell outside its frame."""
        return int(round(self.tolerance_ns() or 0.0))

    def add(self, camera: str, stamp_ns: int, item: Any) -> tuple[list[SyncedFrame], list[SyncIssue]]:
        """Add one camera's item; returns the frames it completes and any issues."""
        stamp_ns = int(stamp_ns)
        if camera not in self._queues:
            return [], [SyncIssue("unknown_camera", stamp_ns, (camera,),
                                  f"message from unknown camera {camera!r} at stamp {stamp_ns} ns "
                                  f"(expected one of {', '.join(self.cameras)})")]
        last = self._last_stamp[camera]
        if last is not None and stamp_ns <= last:
            kind = "duplicate" if stamp_ns == last else "out_of_order"
            return [], [SyncIssue(kind, stamp_ns, (camera,),
                                  f"camera {camera!r}: stamp {stamp_ns} ns is not after its previous stamp "
                                  f"{last} ns ({kind.replace('_', ' ')}); message ignored")]
        if self._last_emitted is not None and stamp_ns <= self._last_emitted:
            return [], [SyncIssue("out_of_order", stamp_ns, (camera,),
                                  f"camera {camera!r}: stamp {stamp_ns} ns arrived after its frame was already "
                                  "emitted; message ignored")]
        if last is not None and not self._given_period:
            self.period_ns = min(stamp_ns - last, self.period_ns or stamp_ns - last)
        self._last_stamp[camera] = stamp_ns
        self._queues[camera].append((stamp_ns, item))
        frames, issues = self._emit()
        if len(self._queues[camera]) > self.max_pending:
            more, why = self._emit_oldest("overflow", f"more than {self.max_pending} items of camera {camera!r} "
                                                      "waiting")
            frames += more
            issues += why
            extra, later = self._emit()
            frames += extra
            issues += later
        return frames, issues

    def _members(self, force: bool) -> tuple[int, dict[str, tuple[int, Any]]] | None:
        """The oldest frame's earliest stamp and its items, if it can be emitted (``force``: whatever waits)."""
        heads = {c: q[0] for c, q in self._queues.items() if q}
        if not heads:
            return None
        t0 = min(s for s, _ in heads.values())
        tol = self.tolerance_ns()
        members = {c: h for c, h in heads.items() if h[0] <= t0 + self._tolerance_whole_ns()}
        decided = len(heads) == len(self.cameras) and (tol is not None or len(members) == len(self.cameras))
        return (t0, members) if decided or force else None

    def _take(self, t0: int, members: dict[str, tuple[int, Any]], kind: str, why: str
              ) -> tuple[SyncedFrame, list[SyncIssue]]:
        for c in members:
            self._queues[c].popleft()
        self._last_emitted = t0 + self._tolerance_whole_ns()
        stamps = tuple(members[c][0] if c in members else None for c in self.cameras)
        frame = SyncedFrame(next(s for s in stamps if s is not None),
                            tuple(members[c][1] if c in members else None for c in self.cameras), stamps)
        missing = tuple(c for c in self.cameras if c not in members)
        if not missing:
            return frame, []
        return frame, [SyncIssue(kind, frame.stamp_ns, missing,
                                 f"frame at stamp {frame.stamp_ns} ns tracked without camera(s) {', '.join(missing)} "
                                 f"({why})")]

    def _emit(self) -> tuple[list[SyncedFrame], list[SyncIssue]]:
        frames, issues = [], []
        while (found := self._members(force=False)) is not None:
            frame, why = self._take(*found, "incomplete", "a later image of theirs came first")
            frames.append(frame)
            issues += why
        return frames, issues

    def _emit_oldest(self, kind: str, why: str) -> tuple[list[SyncedFrame], list[SyncIssue]]:
        found = self._members(force=True)
        if found is None:
            return [], []
        frame, issues = self._take(*found, kind, why)
        return [frame], issues

    def expire(self, why: str = "timed out") -> tuple[list[SyncedFrame], list[SyncIssue]]:
        """Stop waiting for the cameras missing from the oldest frame: emit it with those it has (none waiting:
        nothing)."""
        return self._emit_oldest("incomplete", why)

    def flush(self) -> tuple[list[SyncedFrame], list[SyncIssue]]:
        """Emit every frame still waiting (call at the end of a sequence)."""
        frames, issues = [], []
        while any(self._queues.values()):
            more, why = self._emit_oldest("incomplete", "end of input")
            frames += more
            issues += why
        return frames, issues
