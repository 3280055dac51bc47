"""Per-camera image features for one frame: appearance log-likelihood-ratio maps and grid flow.

``FeatureExtractor`` is fed a camera's RGB frames in order and returns ``FrameFeatures`` for
each: per part class (head, torso, legs, feet) the clipped map log p_fg,c(m) - log p_bg(m)
on the image downsampled by ``downsample`` (paper Sec. 5.1 and footnote 1: the likelihood
sums these ratios over the pixels a hypothesised body covers), and the flow grid of
``vision.flow``.

Learning, in order of preference (all automatic, no hand labels needed):
1. Background: frames known to be background-only (``background_frames`` > 0, e.g. the frames before the start
   description's ``frame``) give the per-pixel mean and pooled covariance. A model learned beforehand can be
   given instead (``use_background``: offline, ``awalker track`` fits ``fit_background_robust`` to frames spread
   over the whole recording, where the person has left every pixel they covered at first). Otherwise the first
   ``median_frames`` frames are buffered and the background is learned robustly from them
   (``fit_background_robust``: per pixel the densest colour cluster); until then the maps are zero (no
   appearance information). It is learned again from the frames so far (at most ``refit_keep`` of them, evenly
   spread) after each of ``refit_frames`` frames: a person who walks along a camera's view covers the same
   pixels for much of the first frames, and that "ghost" fades as the frames where the person has moved on
   outnumber them; the foreground mixtures (2.) are learned again with it, since a person in the first frames'
   background taught them the wrong blob. These counts are frames at ``SCHEDULE_RATE_HZ`` (30 per second) of the
   camera's own time: given the frames' stamps, a 60 Hz camera learns after as many seconds as a 30 Hz one (and
   buffers at most 30 frames a second), where counted in its own frames it learned in half the time, too soon
   for a person walking along the view to have moved off their first pixels.
2. Foreground: at the first frame after the background is known, the mixtures are fitted to
   the interior pixels of the foreground (``learn_foreground``), labelled by (a) a class-label image passed
   with that frame: a user's label mask, or the body projected at the start description's
   pose (``foreground.start_pose_labels``) with the foreground pixels it misses (the start's
   leg phase is unknown) filled by (b); else (b) horizontal bands of the largest foreground
   blob at the body's proportions (head, torso, legs, feet from the top).
Maps are zero before the models exist; the flow is valid from the second frame on.
Illumination: each frame's global per-channel gain relative to the first frame
(``illumination_gains``, a median ratio) is divided out of its measurements before learning
and comparing (``compensate_gain``), so slow or sudden lighting changes do not turn the whole
background into foreground.
Occlusion mask (255 / True = occluded): its pixels get ratio 0, cells it touches are invalid.

Two cores: a frame's grey image and flow are computed on a worker thread of the extractor while the calling
thread learns and computes the maps (OpenCV's DIS and the compiled kernels release the interpreter lock; the
two share no data, so the features are the same as one after the other). ``submit`` returns once the maps are
made, with a future of the features done when the flow is: the caller goes on with the next frame (decoding
it, its maps) while this one's flow is estimated, at most ``MAX_PENDING_FLOWS`` frames behind. The maps take
two compiled calls a frame once the models are learned (measurements in the reference lighting, then the
ratios): each return to Python must take the interpreter lock back, which can cost a switch interval while
another thread runs Python. One thread (``blocks.thread_count``, e.g. ``AWALKER_THREADS=1``) runs them one
after the other.
"""
from __future__ import annotations

import os
import sys
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from awalker_tracker.blocks import thread_count
from awalker_tracker.model.body import PART_CLASSES, BodyDescription
from awalker_tracker.vision.background import (
    BackgroundModel,
    fit_background,
    fit_background_robust,
    measurements,
)
from awalker_tracker.vision.flow import FlowConfig, FlowGrid, GridFlow, to_grey
from awalker_tracker.vision.foreground import ForegroundModel, learn_foreground


#: Map pixels across the image that a rig of two cameras or more aims at (``map_downsample``): 4 x 4 image
#: pixels per map pixel at 640x480, the paper's video, and 2 x 2 at 320x240.
MULTI_CAMERA_MAP_WIDTH = 160
#: Frames whose maps are made but whose flow is not (``FeatureExtractor.submit``) before the next waits.
MAX_PENDING_FLOWS = 2
#: The frame rate the robust background's schedule counts frames at (``FeatureConfig.median_frames``).
SCHEDULE_RATE_HZ = 30.0


@dataclass(frozen=True)
class FeatureConfig:
    """Feature extraction settings. downsample: map pixel = downsample x downsample image px."""

    downsample: int = 4
    background_frames: int = 0        # known background-only frames at the start (0 = unknown)
    # frames at SCHEDULE_RATE_HZ (module doc): buffered for the robust background when none are known, and the
    # robust background learned again after these
    median_frames: int = 20
    refit_frames: tuple[int, ...] = (25, 30, 35, 40, 50, 60, 75, 90, 120)
    refit_keep: int = 30              # at most this many frames (evenly spread) per robust refit
    outlier_probability: float = 0.02  # uniform outlier share of both appearance densities
    llr_clip: float = 25.0            # |log-likelihood ratio| bound per pixel (a safety net)
    adapt_rate: float = 0.0           # background adaptation per frame (0 = frozen)
    compensate_gain: bool = True      # divide out global per-channel illumination changes
    flow: FlowConfig = field(default_factory=FlowConfig)
    seed: int = 0

    def __post_init__(self) -> None:
        if (not 0 < self.outlier_probability < 1 or self.downsample < 1 or self.background_frames < 0
                or self.median_frames < 1 or self.llr_clip <= 0 or self.refit_keep < 2
                or any(f < 1 for f in self.refit_frames)):
            raise ValueError(f"invalid FeatureConfig {self}")
        if not 0.0 <= self.adapt_rate <= 1.0:
            raise ValueError("FeatureConfig.adapt_rate must be in [0, 1]")


def map_downsample(image_width: int, cameras: int) -> int:
    """Image pixels per map pixel (each way) for a rig of ``cameras`` cameras whose images are ``image_width``
    px wide: one camera keeps ``FeatureConfig.downsample`` (4); two or more the whole number that makes the
    map closest to ``MULTI_CAMERA_MAP_WIDTH`` pixels wide (at least 1). (`awalker track` sets the features
    nodes' ``downsample`` with it.)

    Why: at 320x240 a fixed 4 makes a map 80 pixels wide, where a person 5 m away is ~17 map pixels tall,
    a leg less than one wide and one map row ~0.2-0.3 m of depth. With two cameras the finer maps tracked
    the real-walks benchmark closer (docs/tracking.md, "Image features"); with one
    camera they did not (worse on 3 of 12 walks, by 40-50 mm: the sharper likelihood holds depth and which
    leg is which no better), so it keeps the coarser maps."""
    if image_width < 1 or cameras < 1:
        raise ValueError(f"map_downsample: image width {image_width} px and {cameras} cameras; both must be >= 1")
    if cameras < 2:
        return FeatureConfig.downsample
    return max(1, round(image_width / MULTI_CAMERA_MAP_WIDTH))


@dataclass(frozen=True, eq=False)
class FrameFeatures:
    """Features of one camera frame: llr (C, h, w) float32 per ``classes``; flow grid; sizes in px;
    ``occlusion`` (h, w) bool, the map pixels under the camera's occlusion mask (None: no mask)."""

    classes: tuple[str, ...]
    llr: np.ndarray
    downsample: int
    image_width: int
    image_height: int
    flow: FlowGrid
    occlusion: np.ndarray | None = None

    @property
    def map_shape(self) -> tuple[int, int]:
        return int(self.llr.shape[1]), int(self.llr.shape[2])


def blank_features(like: FrameFeatures, width: int, height: int) -> FrameFeatures:
    """Features that carry no evidence (zero maps, no valid flow) of a ``width`` x ``height`` image, with ``like``'s
    part classes, map downsampling and flow cells: a frame a camera has no image in."""
    d = like.downsample
    return FrameFeatures(like.classes, np.zeros((len(like.classes), height // d, width // d), np.float32), d,
                         width, height, FlowGrid.empty(height, width, like.flow.cell_size))


def occlusion_map_mask(mask: np.ndarray | None, downsample: int, shape: tuple[int, int]) -> np.ndarray | None:
    """A full-resolution occlusion mask -> (h, w) bool: any occluded pixel in a block occludes it."""
    if mask is None:
        return None
    m = np.asarray(mask) > 0
    h, w = shape
    if m.shape == (h, w):
        return m
    return m[: h * downsample, : w * downsample].reshape(h, downsample, w, downsample).any(axis=(1, 3))


def occlusion_cell_mask(mask: np.ndarray | None, rows: int, cols: int, size: int) -> np.ndarray | None:
    """A full-resolution occlusion mask -> (rows, cols) bool: any occluded pixel in a flow cell occludes it."""
    if mask is None:
        return None
    m = np.asarray(mask) > 0
    return m[: rows * size, : cols * size].reshape(rows, size, cols, size).any(axis=(1, 3))


def occluded(features: FrameFeatures, mask: np.ndarray | None) -> FrameFeatures:
    """``features`` with a full-resolution occlusion mask (H, W; nonzero = occluded) applied: the map
    pixels it touches get ratio 0 and are marked in ``occlusion``, the flow cells it touches are invalid.
    The one place the mask is applied (the likelihood reads the features as they come)."""
    map_mask = occlusion_map_mask(mask, features.downsample, features.map_shape)
    if map_mask is None:
        return features
    flow = features.flow
    cell_mask = occlusion_cell_mask(mask, *flow.shape, flow.cell_size)
    if cell_mask.any():
        flow = FlowGrid(flow.centers, flow.flow, flow.covariance, flow.valid & ~cell_mask, flow.cell_size)
    return FrameFeatures(features.classes, np.where(map_mask[None], np.float32(0), features.llr),
                         features.downsample, features.image_width, features.image_height, flow, map_mask)


class FeatureExtractor:
    """Streaming feature extraction for one camera (see the module docstring)."""

    def __init__(self, config: FeatureConfig = FeatureConfig(), body: BodyDescription | None = None,
                 classes: tuple[str, ...] = PART_CLASSES, verbose: bool = False) -> None:
        self.config = config
        self.body = body or BodyDescription.default()
        self.classes = classes
        self.verbose = verbose
        self.background: BackgroundModel | None = None
        self.foreground: ForegroundModel | None = None
        self.frame_index = 0
        self.background_frames = config.background_frames
        self._buffer: list[np.ndarray] = []
        self._refits: list[int] = []           # frame counts after which the robust background is refitted
        self._given_background = False         # the background came from ``use_background``: not refitted
        self._first_stamp_ns: int | None = None
        self._schedule_frame = 0                # frames so far at SCHEDULE_RATE_HZ (module doc)
        self._flow = GridFlow(config.flow)
        self._prev_grey: np.ndarray | None = None
        self.image_size: tuple[int, int] | None = None   # (width, height) of the frames submitted so far
        self._pending: deque[Future] = deque()    # flows of submitted frames, oldest first (done ones too)
        self._flow_thread: ThreadPoolExecutor | None = None
        self._flow_thread_pid = 0       # the process that started it (a forked child starts its own)

    @property
    def ready(self) -> bool:
        """True once background and foreground models exist (maps carry information)."""
        return self.background is not None and self.foreground is not None

    def set_background_frames(self, count: int) -> None:
        """Declare the first ``count`` frames background-only (e.g. from the start description).
        Ignored once the background exists or when frames beyond ``count`` were already seen."""
        if self.background is None and int(count) > self.frame_index:
            self.background_frames = int(count)

    def use_background(self, background: BackgroundModel) -> None:
        """Take ``background`` as the camera's background model before the first frame: one learned beforehand,
        e.g. by ``awalker track`` from frames spread over the whole recording (module doc, 1.). It is not learned
        again; the foreground mixtures are learned when they would be with the robust background, after
        ``median_frames`` frames and again after each of ``refit_frames`` (docs/tracking.md, Image features: learned
        at the first frame instead, a person starting from standing was seen 7 % shorter and tracked 104 -> 261 mm
        in the accuracy tests' hands-off walk). ValueError once frames were processed."""
        if self.frame_index:
            raise ValueError(f"use_background: {self.frame_index} frames were already processed")
        self.background, self.foreground = background, None
        self.background_frames, self._buffer = 0, []
        self._given_background = True
        self._refits = sorted(self.config.refit_frames)

    def _labels_at_map(self, labels: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        labels = np.asarray(labels)
        if labels.shape == shape:
            return labels
        d = self.config.downsample
        return labels[d // 2 :: d, d // 2 :: d][: shape[0], : shape[1]]

    def _flow_step(self, image: np.ndarray) -> FlowGrid:
        """The flow from the previous frame's grey image to this one's (kept for the next frame); empty for the
        first frame and after a change of size. Steps run one at a time, in the frames' order."""
        grey = to_grey(image)
        previous, self._prev_grey = self._prev_grey, grey
        if previous is None or previous.shape != grey.shape:
            return FlowGrid.empty(grey.shape[0], grey.shape[1], self.config.flow.cell_size)
        return self._flow.estimate(previous, grey)

    def _flow_worker(self) -> ThreadPoolExecutor | None:
        """The extractor's flow thread when the process may use two threads or more, else None. A forked child
        starts one of its own and forgets the frames its parent had in work (they are done in the parent)."""
        if thread_count() < 2:
            return None
        if self._flow_thread is None or self._flow_thread_pid != os.getpid():
            self._flow_thread = ThreadPoolExecutor(max_workers=1, thread_name_prefix="awalker-flow")
            self._flow_thread_pid = os.getpid()
            self._pending.clear()
        return self._flow_thread

    def _blank_flow_step(self, width: int, height: int) -> FlowGrid:
        """The flow of a frame without an image: none; the next frame's flow starts afresh (not across the gap)."""
        self._prev_grey = None
        return FlowGrid.empty(height, width, self.config.flow.cell_size)

    def _start_flow(self, worker: ThreadPoolExecutor | None, step: Any, *args: Any) -> Future:
        """``step(*args)`` (a flow step of this frame): on ``worker``, or done here without one (a future either
        way). Steps run in the frames' order."""
        if worker is not None:
            return worker.submit(step, *args)
        done: Future = Future()
        try:
            done.set_result(step(*args))
        except Exception as exc:
            done.set_exception(exc)
        return done

    def close(self) -> None:
        """Wait until every submitted frame is done (its future's callbacks too) and stop the worker thread
        (a later frame starts another)."""
        if self._flow_thread is not None and self._flow_thread_pid == os.getpid():
            self._flow_thread.shutdown(wait=True)
        self._flow_thread = None
        self._pending.clear()

    def _log(self, text: str) -> None:
        if self.verbose:
            print(f"features: {text}", file=sys.stderr, flush=True)

    @property
    def learns_foreground_next(self) -> bool:
        """True when the next frame is the one the foreground mixtures will be learned from
        (known background frames only; with the robust fit it is not known in advance)."""
        return self.foreground is None and 0 < self.background_frames == self.frame_index

    def process(self, rgb: np.ndarray, occlusion_mask: np.ndarray | None = None,
                class_labels: np.ndarray | None = None, fill_with_bands: bool = False,
                stamp_ns: int | None = None) -> FrameFeatures:
        """Features of the next frame (RGB (H, W, 3) uint8); updates the models as described above.
        ``class_labels`` (and ``fill_with_bands``) are used if this frame learns the foreground; ``stamp_ns``: the
        frame's time (without it, frames are taken ``SCHEDULE_RATE_HZ`` apart)."""
        return self.submit(rgb, occlusion_mask, class_labels, fill_with_bands, stamp_ns).result()

    def _schedule(self, stamp_ns: int | None) -> bool:
        """Advance the robust background's clock to this frame; True if the frame counts as a new frame at
        ``SCHEDULE_RATE_HZ`` (the first frame, and then one per 1/30 s of stamps)."""
        if stamp_ns is None:
            self._schedule_frame += 1
            return True
        if self._first_stamp_ns is None:
            self._first_stamp_ns = int(stamp_ns)
        counted = int(np.floor((int(stamp_ns) - self._first_stamp_ns) * 1e-9 * SCHEDULE_RATE_HZ + 1e-6)) + 1
        if counted <= self._schedule_frame:
            return False
        self._schedule_frame = counted
        return True

    def submit(self, rgb: np.ndarray, occlusion_mask: np.ndarray | None = None,
               class_labels: np.ndarray | None = None, fill_with_bands: bool = False,
               stamp_ns: int | None = None) -> Future:
        """``process`` that returns once the frame's maps are made (the models learned from it): a future of its
        FrameFeatures, done when its flow is, on the worker thread; frames are done in the order submitted. At
        most ``MAX_PENDING_FLOWS`` frames wait for their flow: a further one waits here for the oldest.
        ValueError (raised here) for an image that is not RGB or not the size of the first frames."""
        cfg = self.config
        image = np.asarray(rgb)
        if image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"expected an (H, W, 3) RGB image, got shape {image.shape}")
        height, width = image.shape[:2]
        if self.background is not None and self.background.shape != (height // cfg.downsample, width // cfg.downsample):
            raise ValueError(f"frame size {width}x{height} differs from the first frames'")
        worker = self._flow_worker()
        while len(self._pending) >= MAX_PENDING_FLOWS:
            self._pending.popleft().exception()     # waits; its own future carries any error
        flow = self._start_flow(worker, self._flow_step, image)
        try:
            llr = self._maps(image, class_labels, fill_with_bands, self._schedule(stamp_ns))
        except BaseException:
            flow.exception()            # this frame's flow step still runs (and keeps its grey image)
            raise
        self.image_size = (width, height)
        return self._features(flow, llr, width, height, occlusion_mask)

    def submit_blank(self, width: int, height: int) -> Future:
        """A frame whose image could not be read (``submit``'s future): it counts as a frame (the background-only
        frames and the frame numbers stay true), its maps are zero (no evidence either way), it has no flow and
        the next frame's flow does not reach back across it; the models learn nothing from it (the frame that was
        to teach the foreground hands that to the next frame)."""
        cfg = self.config
        if self.learns_foreground_next:
            self.background_frames += 1
        worker = self._flow_worker()
        while len(self._pending) >= MAX_PENDING_FLOWS:
            self._pending.popleft().exception()
        flow = self._start_flow(worker, self._blank_flow_step, int(width), int(height))
        llr = np.zeros((len(self.classes), int(height) // cfg.downsample, int(width) // cfg.downsample), np.float32)
        return self._features(flow, llr, int(width), int(height), None)

    def _features(self, flow: Future, llr: np.ndarray, width: int, height: int,
                  occlusion_mask: np.ndarray | None) -> Future:
        """Count the frame; a future of its FrameFeatures, done when its ``flow`` is."""
        cfg = self.config
        self.frame_index += 1
        features: Future = Future()

        def finish(done: Future) -> None:
            try:
                features.set_result(occluded(FrameFeatures(self.classes, llr, cfg.downsample, width, height,
                                                           done.result()), occlusion_mask))
            except BaseException as exc:
                features.set_exception(exc)

        self._pending.append(flow)
        flow.add_done_callback(finish)
        return features

    def _maps(self, image: np.ndarray, class_labels: np.ndarray | None, fill_with_bands: bool,
              counts: bool = True) -> np.ndarray:
        """The log-likelihood-ratio maps (C, h, w) float32 of a frame, after learning what this frame teaches
        the background and foreground models (module doc); ``counts``: a new frame of the robust background's
        schedule (it is buffered, and may end a stage)."""
        cfg = self.config
        height, width = image.shape[:2]
        shape = (height // cfg.downsample, width // cfg.downsample)
        reference = None
        if cfg.compensate_gain:
            # Lighting: measurements are expressed in the illumination of the first frame seen.
            reference = self.background.mean if self.background is not None else (
                self._buffer[0] if self._buffer else None)
            if reference is not None and reference.shape[:2] != shape:
                reference = None
        m = measurements(image, cfg.downsample, reference)
        # ---- model learning ----------------------------------------------------------------
        if self.background is None:
            known = self.background_frames > 0
            if known and self.frame_index < self.background_frames:
                self._buffer.append(m)
            elif known and self._buffer:
                self.background = fit_background(np.stack(self._buffer))
                self._buffer = []
            elif counts:
                self.background_frames = 0     # nothing known to be background: robust fit
                self._buffer.append(m)
                if self._schedule_frame >= cfg.median_frames:
                    self.background = fit_background_robust(np.stack(self._buffer))
                    self._refits = sorted(f for f in cfg.refit_frames if f > self._schedule_frame)
                    if not self._refits:
                        self._buffer = []
            if self.background is not None:
                self._log(f"background learned at frame {self.frame_index}")
        elif self._refits and counts:
            if not self._given_background:      # a given background is kept: only the foreground is relearned
                self._buffer.append(m)
            if self._schedule_frame >= self._refits[0]:
                self._refits.pop(0)
                if not self._given_background:
                    keep = np.linspace(0, len(self._buffer) - 1,
                                       min(len(self._buffer), cfg.refit_keep)).round().astype(int)
                    self.background = fit_background_robust(np.stack([self._buffer[k] for k in keep]))
                    self._log(f"background learned again at frame {self.frame_index} from {len(keep)} of its "
                              f"{len(self._buffer)} frames")
                self.foreground = None          # learned again below, against the new background or with the
                                                # person further in view
                if not self._refits:
                    self._buffer = []
        if self.background is not None and self.foreground is None and (
                self.background_frames == 0 or self.frame_index >= self.background_frames) and (
                not self._given_background or self._schedule_frame >= cfg.median_frames):
            labels = None if class_labels is None else self._labels_at_map(class_labels, m.shape[:2])
            self.foreground = learn_foreground(m, self.background, labels, self.body, self.classes, seed=cfg.seed,
                                               fill_with_bands=fill_with_bands)
            self._log(f"foreground mixtures learned at frame {self.frame_index} from "
                      f"{'a label image' if labels is not None else 'height bands of the foreground blob'}")
        # ---- maps ------------------------------------------------------------------------
        if self.ready:
            llr = self.foreground.log_likelihood_ratios(m, self.background, cfg.llr_clip, cfg.outlier_probability)
            if cfg.adapt_rate > 0:
                self.background = self.background.adapt(m, cfg.adapt_rate)
        else:
            llr = np.zeros((len(self.classes),) + m.shape[:2], np.float32)
        return llr
