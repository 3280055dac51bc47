"""Pair per-camera messages by exact stamp (a small, tested replacement for message_filters).

Each camera delivers its items in increasing stamp order. A frame is emitted as soon as every
camera has delivered an item with its stamp; frames come out in increasing stamp order. Nothing
is dropped silently: every discarded item or incomplete frame is returned as a ``SyncIssue``
(late or duplicate stamp, unknown camera, a frame some cameras never delivered, queue overflow).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class SyncedFrame:
    """Items of all cameras for one stamp, in the synchroniser's camera order."""

    stamp_ns: int
    items: tuple[Any, ...]


@dataclass(frozen=True)
class SyncIssue:
    """Something that could not be paired, with a message naming camera and stamp."""

    kind: str                      # out_of_order | duplicate | unknown_camera | incomplete | overflow
    stamp_ns: int
    cameras: tuple[str, ...]       # the offending camera, or the cameras missing from a frame
    message: str


class StampSynchronizer:
    """Exact-stamp synchroniser for C cameras with at most ``max_pending`` incomplete frames."""

    def __init__(self, cameras: Sequence[str], max_pending: int = 30) -> None:
        if not cameras:
            raise ValueError("StampSynchronizer needs at least one camera")
        if len(set(cameras)) != len(cameras):
            raise ValueError(f"camera names must be unique, got {list(cameras)}")
        if max_pending < 1:
            raise ValueError(f"max_pending must be >= 1, got {max_pending}")
        self.cameras = tuple(cameras)
        self.max_pending = int(max_pending)
        self._pending: dict[int, dict[str, Any]] = {}
        self._last_stamp = {c: None for c in self.cameras}   # last accepted stamp per camera
        self._last_emitted: int | None = None

    @property
    def pending_stamps(self) -> list[int]:
        return sorted(self._pending)

    def _missing(self, stamp: int) -> tuple[str, ...]:
        got = self._pending.get(stamp, {})
        return tuple(c for c in self.cameras if c not in got)

    def _drop(self, stamp: int, kind: str, why: str) -> SyncIssue:
        missing = self._missing(stamp)
        del self._pending[stamp]
        return SyncIssue(kind, stamp, missing,
                         f"frame at stamp {stamp} ns dropped ({why}): no message from camera(s) {', '.join(missing)}")

    def add(self, camera: str, stamp_ns: int, item: Any) -> tuple[list[SyncedFrame], list[SyncIssue]]:
        """Add one camera's item; returns the frames it completes and any issues."""
        stamp_ns = int(stamp_ns)
        if camera not in self._last_stamp:
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
                                  f"camera {camera!r}: stamp {stamp_ns} ns arrived after frame "
                                  f"{self._last_emitted} ns was already emitted; message ignored")]
        self._last_stamp[camera] = stamp_ns
        self._pending.setdefault(stamp_ns, {})[camera] = item
        issues: list[SyncIssue] = []
        frames: list[SyncedFrame] = []
        if len(self._pending[stamp_ns]) == len(self.cameras):
            # Cameras deliver in order, so no earlier incomplete frame can ever complete now.
            for older in [s for s in sorted(self._pending) if s < stamp_ns]:
                issues.append(self._drop(older, "incomplete", f"a later frame {stamp_ns} ns completed first"))
            got = self._pending.pop(stamp_ns)
            frames.append(SyncedFrame(stamp_ns, tuple(got[c] for c in self.cameras)))
            self._last_emitted = stamp_ns
        while len(self._pending) > self.max_pending:
            issues.append(self._drop(min(self._pending), "overflow",
                                     f"more than {self.max_pending} incomplete frames waiting"))
        return frames, issues

    def discard(self, stamp_ns: int, why: str = "timed out") -> SyncIssue | None:
        """Give up on one incomplete frame (e.g. a camera's message never came); None if not pending."""
        if int(stamp_ns) not in self._pending:
            return None
        self._last_emitted = max(int(stamp_ns), self._last_emitted or int(stamp_ns))
        return self._drop(int(stamp_ns), "incomplete", why)

    def flush(self) -> list[SyncIssue]:
        """Report and forget every incomplete frame (call at the end of a sequence)."""
        return [self._drop(s, "incomplete", "end of input") for s in sorted(self._pending)]
