"""`awalker track` in one process: replay (lockstep) -> features (one node per camera) ->
tracker -> pose publisher, the same node classes a user starts separately. The feature nodes spin
in their own thread (their OpenCV and numba work releases the GIL), one frame ahead of the
tracker, which spins with the rest in the main thread.

Writes into the output directory:
- ``result.bag``: every topic the pipeline published (features, posterior, joint states, markers,
  acks), recorded from the topics themselves;
- ``poses.csv`` (MAP trajectory: lineage of the final best particle; ``frame,stamp_ns,marker,x,y,z``)
  and ``summary.csv`` (per frame: posterior speed, stance-left probability, N_eff, resampling,
  heel strike, MAP stance leg);
- ``calibration.yaml``, ``start.yaml``, ``body.yaml`` (what was used) and ``run.yaml`` (input,
  settings, timings);
- ``overlay/frame_XXXXX.png`` and ``overlay.mp4``: the MAP body drawn on the first camera's frames.

With no body description (the tracker scales one to the person's height seen in the images), or with
``TrackOptions.fit_body``, it tracks twice: a first pass into ``first_pass/``, the leg length fitted to
the image features that pass recorded (``awalker_tools.fit_body``, issue 12 §3), and the run again
with the fitted body, whose outputs are the ones above (run.yaml's ``body_fit`` says what the fit chose).
A start that names no stance leg (found automatically, or ``stance_leg: unknown``) also takes the first
pass, and its leg is weighed there (``inference.bodyfit.fit_stance_leg``) and handed to the second pass's
tracker (``TrackOptions.fitted_start``); the body, when given, is kept as it is.
The first pass stops once it has filtered the frames the fit uses (``BodyFitConfig.frames`` from the
start), with few particles (``FIRST_PASS_PARTICLES``: its own track is not used), so a long bag is tracked
about once, not twice.
"""
from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from awalker_tracker.errors import InputError
from awalker_tracker.inference.filter_model import StartDescription, TrackerConfig
from awalker_tracker.inference.profiles import DEFAULT_PROFILE, PROFILES, particle_count_text, tracking_profile
from awalker_tracker.inference.sync import DEFAULT_TOLERANCE
from awalker_tracker.model.body import BodyDescription, seen_height_measured
from awalker_tracker.model.walker import LEG_NAMES

from awalker_tools import evaluation
from awalker_tools.outdir import INCOMPLETE_KEY, RESULT_BAG, files_under, prepare_output_dir, record_written

DEFAULTS = PROFILES[DEFAULT_PROFILE]
START_FILE, BODY_FILE, CALIBRATION_FILE, RUN_FILE = "start.yaml", "body.yaml", "calibration.yaml", "run.yaml"
PROGRESS_PERIOD_S = 2.0
#: What a run writes at the top of its output folder (a file of the user's there stops a --force run).
TRACK_OUTPUTS = (RESULT_BAG, RUN_FILE, CALIBRATION_FILE, START_FILE, BODY_FILE, "poses.csv", "summary.csv",
                 "gait.csv", "gait.json", "gait.png", "overlay", "overlay.mp4", "first_pass")
#: Lockstep replay lets this many frames out beyond the oldest the tracker has not acknowledged, so the
#: feature thread works on the next frames while the tracker filters this one, and a frame that takes the
#: filter longer (a look-ahead re-simulation after resampling) does not leave the feature thread idle.
#: The features depend on the images, masks and descriptions only, so the results do not depend on it.
FRAMES_AHEAD = 3
#: s: how long a thread may hold the GIL while another waits (Python's default 0.005). The feature thread's
#: OpenCV and numba calls give up the GIL and must win it back from the main thread's Python (the filter's
#: glue, the messages) after each; a shorter slice lets them back sooner. Measured (four alternate fresh runs
#: of `awalker track bags/walk.bag --no-overlay` each): 500 particles 27.4-33.0 -> 29.5-33.8
#: frames/s, 5000 14.9-16.7 -> 15.3-16.8 (no pair slower).
GIL_SWITCH_INTERVAL_S = 0.001
#: Seconds the replay waits for the tracker to acknowledge a frame before giving up. The first frames the
#: tracker filters compile its numba kernels on a fresh install (~25 s on an idle 2-core machine; a first
#: run beside three other jobs took over the replay's default 60 s and stopped); a failure in
#: a node's thread stops the run at once, whatever this says.
ACK_TIMEOUT_S = 600.0
#: Seconds the tracker waits for a camera's features before tracking a frame without it (the node's
#: ``sync_timeout_s``, 2 s live). Offline the replay waits for every frame, so a features thread that falls
#: behind only slows the run: with the node's 2 s, 10 of 80 two-camera benchmark runs on a machine running four
#: trackers at once tracked a frame or two without their second camera.
SYNC_TIMEOUT_S = 60.0
#: Seconds the pipeline waits, after the last frame, for the pose publisher's outputs of every posterior to
#: reach the recorder; if some never do, it says which and how many (they are then missing from result.bag).
RECORD_WAIT_S = 10.0
#: A camera whose first this many images all fail to decode stops the run (a stream the tracker cannot read,
#: found without waiting for the end of the bag); fewer, later or scattered ones are tracked without (run.yaml's
#: ``undecodable_images``).
UNDECODABLE_STOP = 10
#: Frames of each camera, spread evenly over the recording, that a run without known empty frames learns the
#: camera's background from (``recording_backgrounds``).
RECORDING_BACKGROUND_FRAMES = 40


class Interrupted(KeyboardInterrupt):
    """`awalker track` stopped by SIGINT or SIGTERM (its outputs written for the frames done); the command's exit
    status is ``exit_status``, 128 + the signal's number (130, 143)."""

    def __init__(self, signum: int, message: str) -> None:
        super().__init__(message)
        self.exit_status = 128 + int(signum)


class StopRequest:
    """The first SIGINT or SIGTERM of a run (``_stop_on_signals``): the run stops after the frame in work, writes
    its outputs for the frames done and raises ``Interrupted``."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def interrupted(self, what: str) -> Interrupted:
        """The exception ending the run, ``what`` saying where it stopped."""
        assert self.signum is not None
        return Interrupted(self.signum, f"interrupted by {signal.Signals(self.signum).name} {what}")

    def check(self, what: str) -> None:
        """Raise ``interrupted(what)`` once a signal came."""
        if self.signum is not None:
            raise self.interrupted(what)


@contextmanager
def _stop_on_signals(stop: StopRequest) -> Iterator[None]:
    """While the block runs (in the main thread), SIGINT and SIGTERM set ``stop``; a second one raises
    ``Interrupted`` at once, wherever the main thread is. The previous handlers are restored afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: Any) -> None:
        if stop.signum is not None:
            raise Interrupted(signum, f"interrupted by {signal.Signals(signum).name} again: stopped at once")
        stop.signum = signum

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, old in previous.items():
            signal.signal(s, old)


class _SpinThread:
    """An executor spinning its nodes in a background thread; an exception there is kept for ``check``."""

    def __init__(self, executor: Any, nodes: list[Any], name: str) -> None:
        self.executor = executor
        for node in nodes:
            executor.add_node(node)
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._spin, name=name, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except BaseException as exc:    # re-raised in the main thread by check()
            self.error = exc

    def check(self) -> None:
        if self.error is not None:
            raise self.error

    def stop(self) -> None:
        self.executor.shutdown()
        self._thread.join(timeout=10.0)


@dataclass(frozen=True)
class TrackOptions:
    """Settings of one `awalker track` run."""

    bag: Path
    out: Path
    start: Path | None = None
    body: Path | None = None
    # the filter's settings: the default profile's unless given (inference.profiles, as the tracker node's;
    # `awalker track --profile` fills them from the profile it names, and sets ``profile``, whose defaults the
    # tracker node takes for what is left unset here: depth_band_m None)
    profile: str = DEFAULT_PROFILE
    particles: int = DEFAULTS.num_particles
    min_particles: int | None = None   # the adaptive count's fewest (SMCConfig); None: the profile's
    lookahead: int = DEFAULTS.lookahead
    trust: float = DEFAULTS.trust
    seed: int = DEFAULTS.seed
    likelihood_scale: float = DEFAULTS.likelihood_scale
    leg_scale_spread: float = DEFAULTS.leg_scale_spread   # the particles' leg lengths around the body's
    # the particles' pelvis ceilings around this fraction of the walker's hip height, whatever the number of
    # cameras (1: off); None: the tracker's default (TrackerConfig.pelvis_ceiling_for: 0.97 with two or more
    # cameras, off with one)
    pelvis_ceiling: float | None = None
    auto_start: bool = False        # ignore any start description and find the walking person (also when none exists)
    follow_near: tuple[float, float] | None = None   # automatic start: follow the person first seen near this ground point (m)
    recovery: bool = DEFAULTS.recovery   # re-seed fallen walkers, re-acquire a lost track, hold still (recovery.py)
    depth_band_m: float | None = None   # one camera: the feet row's depth band (None: the profile's); off without recovery
    overlays: bool = True
    # two passes, the second with the leg length fitted to the first one's images (module docstring);
    # None: when no body description is found, so that the body would only be scaled to the seen height
    fit_body: bool | None = None
    # a start fitted to these images (`awalker fitbody`'s start_fitted.yaml): a start that names no stance leg
    # takes its leg (the tracker node's fitted_start); set by run_tracking for its second pass
    fitted_start: Path | None = None
    storage: str = "mcap"
    quiet: bool = False
    # False: the pipeline's DDS participants see nothing outside this process (another publisher of
    # /<cam>/image_raw on the host cannot disturb the lockstep replay). True: visible on this host
    # (ROS_DOMAIN_ID) so that RViz or `ros2 topic echo` can watch.
    share_topics: bool = False
    # stop once this many frames have been filtered (from the start frame on); None: the whole bag
    stop_after_frames: int | None = None
    # image pixels per map pixel (each way) of the features nodes; None: vision.features.map_downsample (4 with
    # one camera, maps about 160 pixels wide with two or more); run_tracking's first pass sets 4
    map_downsample: int | None = None
    # ``out`` may hold files: those a previous run listed in its run.yaml are replaced, the others kept
    # (``outdir.prepare_output_dir``); False: ``out`` must be new or empty
    force: bool = False
    # frame periods: images of the cameras whose stamps differ by less make one frame (nearest stamp; 0: equal
    # stamps only); a frame missing a camera is tracked with the others
    sync_tolerance: float = DEFAULT_TOLERANCE


@dataclass
class TrackResult:
    frames: int = 0
    summaries: int = 0
    seconds: float = 0.0            # the whole command: set-up, streaming, writing the outputs (not the pictures)
    seconds_pictures: float = 0.0   # drawing gait.png and the overlays afterwards
    seconds_streaming: float = 0.0  # from the first replayed message to the last posterior received
    seconds_in_filter: float = 0.0
    sync_issues: list[str] = field(default_factory=list)
    depth_band_m: float = 0.0       # the tracker's one-camera depth band (RecoveryConfig.depth_band_m)
    recorded: dict[str, int] = field(default_factory=dict)
    features: dict[str, dict[str, str]] = field(default_factory=dict)   # per camera: how its models were learned
    undecodable: dict[str, int] = field(default_factory=dict)   # per camera: images that could not be decoded
    tracks: list[dict[str, object]] = field(default_factory=list)   # per track: frames and how it ended (track_record)

    @property
    def frames_per_second(self) -> float:
        return self.summaries / self.seconds if self.seconds > 0 else 0.0

    @property
    def streaming_frames_per_second(self) -> float:
        """Frames/s of the running pipeline (replay, features, tracker, pose publisher, recording)."""
        return self.summaries / self.seconds_streaming if self.seconds_streaming > 0 else 0.0


def resolve_descriptions(bag: Path, reader: Any, start_path: Path | None, body_path: Path | None,
                         auto_start: bool = False) -> tuple[StartDescription | None, str, BodyDescription | None, str]:
    """Start and body descriptions: the files given, else the bag's topics, else files beside the bag.
    No start description (or ``auto_start``): None, and the tracker finds the walking person itself; then
    also no body description: None, and the tracker scales one to the person's height."""
    from awalker_tools.bagio import BODY_DESCRIPTION_TOPIC, START_DESCRIPTION_TOPIC

    beside = [bag.parent, bag] if bag.is_dir() else [bag.parent]

    def resolve(parser: Any, path: Path | None, topic: str, file_name: str, kind: str, usage: str | None
                ) -> tuple[Any, str]:
        if path is not None:
            return parser.from_yaml(path), str(path)
        if (text := reader.text(topic)) is not None:
            return parser.from_yaml_text(text, f"{bag}:{topic}"), topic
        if found := [d / file_name for d in beside if (d / file_name).is_file()]:
            return parser.from_yaml(found[0]), str(found[0])
        if usage is None:
            return None, f"none found (no --{kind}, no {topic} topic, no {file_name} beside the bag)"
        raise InputError(f"{bag}: no {kind} description (no {topic} topic, no {file_name} beside the bag); "
                         f"pass --{kind} {usage}")

    if auto_start:
        start, start_src = None, "--auto-start"
    else:
        start, start_src = resolve(StartDescription, start_path, START_DESCRIPTION_TOPIC, START_FILE, "start", None)
    # with an automatic start, a missing body is scaled from the person's height seen in the images
    body, body_src = resolve(BodyDescription, body_path, BODY_DESCRIPTION_TOPIC, BODY_FILE, "body",
                             None if start is None else "BODY.yaml with 'body: {upper_leg_length, lower_leg_length, "
                             "...}' (m)")
    return start, start_src, body, body_src


class Recorder:
    """Records topics as raw CDR into a rosbag2 bag (rosbags Writer) from rclpy subscriptions."""

    def __init__(self, node: Any, path: Path, topics: dict[str, tuple[type, str]], storage: str = "mcap") -> None:
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rosbags.rosbag2 import StoragePlugin, Writer

        from awalker_tools.typestore import typestore

        plugin = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}[storage]
        self.writer = Writer(path, version=9, storage_plugin=plugin)
        self.writer.open()
        self.counts: dict[str, int] = {t: 0 for t in topics}
        self._connections = {}
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        for topic, (cls, msgtype) in topics.items():
            self._connections[topic] = self.writer.add_connection(topic, msgtype, typestore=typestore())
            node.create_subscription(cls, topic, lambda raw, t=topic: self._on(t, raw), qos, raw=True)

    def _on(self, topic: str, raw: bytes) -> None:
        # log time = receive time, as `ros2 bag record` does; the messages carry the image stamps
        self.writer.write(self._connections[topic], time.time_ns(), raw)
        self.counts[topic] += 1

    def close(self) -> None:
        self.writer.close()


def _progress(options: TrackOptions, text: str) -> None:
    if not options.quiet:
        print(text, file=sys.stderr, flush=True)


FIRST_PASS_DIR = "first_pass"
#: Frames the leg fit uses from the start (and the first pass tracks); None: BodyFitConfig's.
FIT_FRAMES: int | None = None
#: Particles of the first pass. The fit reads only what that pass recorded and found without its filter
#: (the image features, the automatic start and the body scaled to the seen height: the start finder's) and
#: runs its own filters (BodyFitConfig.particles), so the first pass's own track needs no more.
FIRST_PASS_PARTICLES = 100


def _new_result_bag(out: Path) -> Path:
    """``out/result.bag``, refused if a run already wrote it."""
    result_bag = out / RESULT_BAG
    if result_bag.exists():
        raise InputError(f"{result_bag}: exists already; choose a new --out directory or remove it")
    return result_bag


def fewest_particles(options: TrackOptions) -> int:
    """The adaptive count's fewest particles of a run (``SMCConfig.min_particles``; 0: ``particles`` throughout):
    ``options.min_particles``, else its profile's, at most ``options.particles`` (as the tracker node takes it)."""
    if options.min_particles is None:
        return tracking_profile(options.profile).fewest_for(options.particles)
    return min(int(options.min_particles), int(options.particles))


def run_tracking(options: TrackOptions) -> TrackResult:
    """Run the whole pipeline on ``options.bag``; write the outputs into ``options.out``. With a body
    to fit (``TrackOptions.fit_body``), a first pass into ``out/first_pass``, the fit, and the run.
    ``out`` must be new or empty (``TrackOptions.force``: see ``outdir.prepare_output_dir``); run.yaml lists
    the files the run wrote, also when it stops on an error (with ``incomplete``: the reason). SIGINT or SIGTERM
    stops it after the frame in work, with poses.csv, summary.csv and gait.csv for the frames done, result.bag
    closed and ``incomplete`` saying so: ``Interrupted`` (exit status 130 or 143)."""
    from awalker_tools.bagio import SequenceReader

    bag = Path(options.bag)
    if not bag.exists():
        raise InputError(f"{bag}: no such bag (expected a rosbag2 directory, .mcap or .db3)")
    out = Path(options.out)
    kept = prepare_output_dir(out, force=options.force, outputs=TRACK_OUTPUTS)
    stop = StopRequest()
    try:
        # (the reader is opened once for every pass: opening parses its metadata, ~30 ms)
        with _stop_on_signals(stop), SequenceReader(bag) as reader:
            _check_image_encodings(bag, reader)
            check_camera_sync(bag, reader, options.sync_tolerance)
            result = _run_passes(options, reader, stop)
    except BaseException as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        if out.is_dir() and files_under(out) - kept:
            record_written(out, kept, {"input": str(bag.resolve()), INCOMPLETE_KEY: reason})
        raise
    record_written(out, kept)
    return result


def _check_image_encodings(bag: Path, reader: Any) -> None:
    """Refuse a camera whose images come in an encoding the tracker cannot decode (judged by its first image:
    damaged data in one image is tracked without that image, an encoding holds for the whole stream)."""
    from awalker_tracker.vision.decode import UnsupportedEncoding

    for camera in reader.cameras:
        if isinstance(error := reader.first_image_error(camera.name), UnsupportedEncoding):
            raise InputError(f"{bag}: {error}")


#: Images per camera whose stamps ``check_camera_sync`` compares.
SYNC_CHECK_IMAGES = 30


def check_camera_sync(bag: Path, reader: Any, tolerance: float) -> None:
    """Refuse cameras whose images would not pair into frames: another camera's first ``SYNC_CHECK_IMAGES`` images
    lying a median of more than ``tolerance`` frame periods from the first camera's nearest (each would be a
    frame of its own, twice as many frames as there are). Also ``awalker info``'s check (``baginfo``)."""
    from awalker_tools.bagio import stamp_ns_of

    def first_stamps(camera: Any) -> tuple[str, np.ndarray]:
        topic, _ = reader.image_topic_of(camera.name)
        stamps = []
        for _, _, _, msg in reader.messages([topic]):
            stamps.append(stamp_ns_of(msg.header))
            if len(stamps) == SYNC_CHECK_IMAGES:
                break
        return topic, np.asarray(stamps, np.int64)

    cameras = reader.cameras
    if len(cameras) < 2:
        return
    first_topic, first = first_stamps(cameras[0])
    if len(first) < 2:
        return
    period = float(np.median(np.diff(first)))
    for camera in cameras[1:]:
        topic, stamps = first_stamps(camera)
        if not len(stamps):
            continue
        apart = float(np.median(np.min(np.abs(stamps[:, None] - first[None, :]), axis=1)))
        if apart > tolerance * period:
            raise InputError(f"{bag}: the images of {topic} lie a median {apart * 1e-6:.1f} ms from the nearest of "
                             f"{first_topic}, more than --sync-tolerance {tolerance:.3g} of a {period * 1e-6:.1f} ms "
                             f"frame; pass --sync-tolerance above {apart / period:.2f} (below 1) to pair them")


def recording_backgrounds(reader: Any, downsample: dict[str, int],
                          count: int = RECORDING_BACKGROUND_FRAMES) -> dict[str, Any]:
    """Camera name -> ``vision.background.BackgroundModel`` learned robustly (``fit_background_robust``) from
    ``count`` of its images spread evenly over the whole recording in ``reader`` (a ``bagio.SequenceReader``), at
    ``downsample[name]`` image px per map px, in the lighting of the first (``measurements``' reference).

    Offline the whole walk is at hand: a person who stood or walked along the camera's view covered the same
    pixels for the first second or two, and a background fitted to those frames alone keeps them (a "ghost" that
    joins the person's blob below the feet: one camera's automatic start up to 0.9 m too near on walks away from
    it, docs/tracking.md).
    Spread over the recording, each pixel shows the person in few of the frames. Images that cannot be decoded
    are left out here (the features node reports them); a camera with fewer than 2 decodable ones is left out of
    the result (its node learns as it would live)."""
    from awalker_tracker.vision.background import fit_background_robust, measurements
    from awalker_tracker.vision.decode import decode_image

    backgrounds = {}
    for name, d in downsample.items():
        found = reader.image_topic_of(name)
        if found is None:
            continue
        topic = found[0]
        total = sum(int(c.msgcount) for c in reader.connections(topic))
        chosen = set(np.linspace(0, total - 1, min(count, total)).round().astype(int).tolist()) if total else set()
        stack: list[np.ndarray] = []
        for index, (_, _, _, msg) in enumerate(reader.messages([topic])):
            if index not in chosen:
                continue
            try:
                rgb = decode_image(msg, topic)
            except InputError:
                continue
            if stack and (rgb.shape[0] // d, rgb.shape[1] // d) != stack[0].shape[:2]:
                continue                    # a frame of another size: the features node reports it
            stack.append(measurements(rgb, d, stack[0] if stack else None))
        if len(stack) >= 2:
            backgrounds[name] = fit_background_robust(np.stack(stack))
    return backgrounds


def _undecodable_camera(features: Sequence[Any], at_end: bool) -> str | None:
    """Why the run cannot go on: a features node none of whose images decoded (its first ``UNDECODABLE_STOP``,
    or with ``at_end`` all it got); None while each camera has decoded images."""
    for node in features:
        stats = node.stats
        if stats.decoded == 0 and stats.undecodable and (at_end or stats.undecodable >= UNDECODABLE_STOP):
            return (f"none of the first {stats.undecodable} images of camera {node.camera_name} could be decoded "
                    f"(the first: {stats.first_undecodable})")
    return None


def _run_passes(options: TrackOptions, reader: Any, stop: StopRequest) -> TrackResult:
    """``run_tracking`` on the bag open in ``reader`` (a ``bagio.SequenceReader``)."""
    from awalker_tools.fit_body import fit_run_dir
    from awalker_tracker.inference.bodyfit import BodyFitConfig
    from awalker_tracker.vision.features import FeatureConfig

    bag, out = Path(options.bag), Path(options.out)
    fit_legs, fit_stance, seen_body = bool(options.fit_body), False, False
    if options.fit_body is not False:
        try:
            start, _, body, _ = resolve_descriptions(bag, reader, options.start, options.body, options.auto_start)
        except InputError:
            return _track_once(options, reader, stop)          # which reports what is missing
        # a body scaled to the seen height (``BodyDescription.from_seen_height``) keeps its legs where two cameras
        # or more measured that height (``seen_height_measured``): the fit, its torso and head giving what
        # the legs gain, chose legs a median 1.1 cm long and the pelvis 30 mm high on the tuning subjects
        # (docs/tracking.md, *Body fit*)
        seen_body = body is None
        fit_legs = fit_legs or (seen_body and not seen_height_measured(len(reader.cameras)))
        fit_stance = start is None or start.stance_leg is None
    if not (fit_legs or fit_stance):
        return _track_once(options, reader, stop)
    if fit_legs and options.pelvis_ceiling is None:
        # A leg fitted to the walking person's images already carries the pelvis where they show it, where the
        # pelvis ceiling lowers a standing (tape) leg to where people walk; both passes keep the pelvis at the
        # walker's hip then (the fit weighs its candidates so too: fit_body). Real walks hands off, two cameras,
        # tracker seeds 0-4 (31 runs): with the ceilings a median +1.3 mm per run (14 of 31 better), 07_01 slow
        # 66.0 -> 83.2 and u-turn 67.2 -> 86.9 mm; the body slides back along the walk as the knee bends.
        options = replace(options, pelvis_ceiling=1.0)
    _new_result_bag(out)         # before the first pass, not after it
    started = time.monotonic()
    first_dir = out / FIRST_PASS_DIR
    fit_frames = FIT_FRAMES or BodyFitConfig().frames
    fitting = " and ".join((["the body's leg length"] if fit_legs else []) + (["the stance leg"] if fit_stance else []))
    _progress(options, f"awalker track: first pass into {first_dir} (its first {fit_frames} tracked frames), to fit "
                       f"{fitting}")
    # The first pass keeps the coarser maps of one camera, whatever the rig: the seen height and the leg fit were
    # measured on them. On the finer maps of two cameras at 320x240 the seen height came out 2 % taller and the
    # fit chose longer legs still (real walks hands off, 07_01 straight, seed 0: 0.917 m against 0.873, the
    # person's 0.807), the pelvis 86 mm high against 41 over 7 runs; the second pass tracks on the finer maps.
    learned: dict[tuple[str, int], Any] = {}          # the recording's backgrounds, learned once for both passes
    _track_once(replace(options, out=first_dir, overlays=False, stop_after_frames=fit_frames,
                        particles=FIRST_PASS_PARTICLES, map_downsample=FeatureConfig.downsample), reader, stop,
                backgrounds=learned)
    stop.check("after the first pass")
    _progress(options, f"awalker track: fitting {fitting} to the images of {first_dir}")
    # the fit's own particle count (BodyFitConfig: 5000; fewer pick less reliably), whatever the run's
    fitted = fit_run_dir(first_dir, None if fit_legs else (1.0,), seed=options.seed, frames=fit_frames,
                         check=lambda: stop.check("during the first pass's fit"))
    chosen = ([f"legs x {fitted['leg_factor']:.2f} (leg length {fitted['leg_length_m']} m"
               + (", the seen height kept" if fitted.get("height_kept") else "") + ")"] if fit_legs else []) + (
        [f"stance leg {fitted['stance_leg']} at the start"] if "stance_leg" in fitted else [])
    _progress(options, f"awalker track: {', '.join(chosen)}; tracking again")
    fitted["seconds_first_pass_and_fit"] = round(time.monotonic() - started, 3)
    # (a body scaled to the seen height is the first pass's: the second pass's finer maps see the person taller)
    second_body = Path(fitted["written"]) if fit_legs else first_dir / BODY_FILE if seen_body else options.body
    second = replace(options, body=second_body,
                     fitted_start=Path(fitted["start_written"]) if "start_written" in fitted else None)
    stop.check("after the first pass's fit")
    return _track_once(second, reader, stop, body_fit=fitted, backgrounds=learned)


def _track_once(options: TrackOptions, reader: Any, stop: StopRequest, body_fit: dict | None = None,
                backgrounds: dict[tuple[str, int], Any] | None = None) -> TrackResult:
    """One pass of the pipeline (``run_tracking``) on the bag open in ``reader`` (a ``bagio.SequenceReader``: its
    descriptions are read through it, and the replay reads the messages through it); ``body_fit``: the fit that
    gave its body, for run.yaml; ``backgrounds``: (camera, map downsampling) -> the recording's background
    (``recording_backgrounds``) learned by an earlier pass, filled with those this one learns; ``stop``: once a
    signal set it, the pass ends after the frame in work, writes its outputs (no pictures) and raises
    ``Interrupted``."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    from awalker_tracker.nodes.base import AwalkerNode, private_node_options
    from awalker_tracker.nodes.features_node import FeatureNode
    from awalker_tracker.nodes.pose_publisher_node import PosePublisherNode
    from awalker_tracker.nodes.tracker_node import TrackerNode
    from awalker_tracker.vision.camera import save_calibration
    from awalker_tracker.vision.features import map_downsample

    from awalker_tools.replay import ReplayConfig, Replayer

    bag, out = Path(options.bag), Path(options.out)
    cameras = reader.cameras
    num_frames = len(reader.frame_stamps)
    start, start_src, body, body_src = resolve_descriptions(bag, reader, options.start, options.body,
                                                            options.auto_start)
    if start is not None and start.frame >= num_frames:
        raise InputError(f"start description ({start_src}): start frame {start.frame} but {bag} has {num_frames} frames")
    out.mkdir(parents=True, exist_ok=True)
    result_bag = _new_result_bag(out)
    save_calibration(cameras, out / CALIBRATION_FILE)
    if start is not None:
        (out / START_FILE).write_text(start.to_yaml_text())
    elif (out / START_FILE).exists():
        (out / START_FILE).unlink()        # the tracker writes the start it finds
    if body is not None:
        (out / BODY_FILE).write_text(body.to_yaml_text())
    elif (out / BODY_FILE).exists():
        (out / BODY_FILE).unlink()         # the tracker writes the body it estimates
    names = [c.name for c in cameras]
    downsample = {c.name: options.map_downsample or map_downsample(c.width, len(cameras)) for c in cameras}
    _progress(options, f"awalker track: {bag} ({num_frames} frames, cameras {', '.join(names)}), "
                       + (f"start frame {start.frame} from {start_src}" if start is not None else
                          f"start description: {start_src}; finding the walking person automatically")
                       + f", body from {body_src}, {particle_count_text(options.particles, fewest_particles(options))}")

    # Read by the rmw when the context starts.
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST" if options.share_topics else "OFF"
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    nodes: list[Any] = []
    recorder = None
    feature_thread: _SpinThread | None = None
    result = TrackResult()
    switch_interval = sys.getswitchinterval()
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    started = time.monotonic()
    try:
        def node_options(overrides: list[Any] | None = None) -> dict[str, Any]:
            """A node's keyword arguments: its parameter overrides, and with the topics private, none of what only
            another process could use (``nodes.base.private_node_options``)."""
            return {"parameter_overrides": list(overrides or [])} if options.share_topics else private_node_options(
                overrides)

        driver = AwalkerNode("awalker_track_replay", context=context, **node_options())
        nodes.append(driver)
        # the features nodes get the same start and body as the tracker (files or bag topics alike)
        features = [FeatureNode(context=context, **node_options([
            Parameter("camera_name", value=c.name),
            Parameter("downsample", value=downsample[c.name]),
            Parameter("start_description", value=str(out / START_FILE) if start is not None else ""),
            Parameter("use_start_description", value=start is not None),
            Parameter("body_description", value=str(out / BODY_FILE) if body is not None else "")])) for c in cameras]
        nodes += features
        if start is None or start.frame < 1:
            # no frames known to be empty: each camera's background from frames spread over the whole recording
            backgrounds = {} if backgrounds is None else backgrounds
            if missing := {n: d for n, d in downsample.items() if (n, d) not in backgrounds}:
                _progress(options, f"awalker track: learning each camera's background from "
                                   f"{RECORDING_BACKGROUND_FRAMES} frames spread over the recording")
                found = recording_backgrounds(reader, missing)
                backgrounds.update({(n, missing[n]): found.get(n) for n in missing})
            for node in features:
                if (learned := backgrounds[(node.camera_name, downsample[node.camera_name])]) is not None:
                    node.use_background(learned, "robust fit (densest colour per pixel) of "
                                        f"{RECORDING_BACKGROUND_FRAMES} frames spread over the recording")
        band = options.depth_band_m if options.recovery else 0.0      # None: the tracker node's default
        tracker = TrackerNode(context=context, **node_options([
            Parameter("cameras", value=names), Parameter("calibration", value=str(out / CALIBRATION_FILE)),
            Parameter("start_description", value=str(out / START_FILE) if start is not None else ""),
            Parameter("auto_start", value=start is None), Parameter("start_output", value=str(out / START_FILE)),
            Parameter("fitted_start", value=str(options.fitted_start or "")),
            *([Parameter("follow_near", value=[float(v) for v in options.follow_near])] if options.follow_near else []),
            Parameter("body_description", value=str(out / BODY_FILE) if body is not None else ""),
            Parameter("estimate_body", value=body is None), Parameter("body_output", value=str(out / BODY_FILE)),
            Parameter("profile", value=options.profile),
            Parameter("num_particles", value=int(options.particles)), Parameter("lookahead", value=int(options.lookahead)),
            *([Parameter("min_particles", value=int(options.min_particles))]
              if options.min_particles is not None else []),
            Parameter("trust", value=float(options.trust)), Parameter("seed", value=int(options.seed)),
            Parameter("likelihood_scale", value=float(options.likelihood_scale)),
            Parameter("leg_scale_spread", value=float(options.leg_scale_spread)),
            *([Parameter("pelvis_ceiling", value=float(options.pelvis_ceiling)),
               Parameter("pelvis_ceiling_min_cameras", value=1)] if options.pelvis_ceiling is not None else []),
            Parameter("reseed_fallen", value=bool(options.recovery)), Parameter("reacquire", value=bool(options.recovery)),
            Parameter("hold_still", value=bool(options.recovery)),
            *([Parameter("depth_band_m", value=float(band))] if band is not None else []),
            Parameter("sync_tolerance", value=float(options.sync_tolerance)),
            Parameter("sync_timeout_s", value=SYNC_TIMEOUT_S),
            Parameter("idle_flush_s", value=1.0e9), Parameter("max_lag_s", value=0.0)]))
        tracker.keep_summaries = True
        nodes.append(tracker)
        poser = PosePublisherNode(context=context, **node_options([
            Parameter("body_description", value=str(out / BODY_FILE) if body is not None else "")]))
        nodes.append(poser)
        from awalker_msgs.msg import GaitStep, ImageFeatures, PosteriorSummary
        from sensor_msgs.msg import JointState, PointCloud2
        from std_msgs.msg import Header
        from visualization_msgs.msg import MarkerArray

        topics: dict[str, tuple[type, str]] = {
            "/awalker/posterior": (PosteriorSummary, "awalker_msgs/msg/PosteriorSummary"),
            "/awalker/joint_states": (JointState, "sensor_msgs/msg/JointState"),
            f"/humans/bodies/{poser.body_id}/joint_states": (JointState, "sensor_msgs/msg/JointState"),
            "/awalker/markers": (MarkerArray, "visualization_msgs/msg/MarkerArray"),
            "/awalker/particles": (PointCloud2, "sensor_msgs/msg/PointCloud2"),
            "/awalker/gait_steps": (GaitStep, "awalker_msgs/msg/GaitStep"),
            "/awalker/ack": (Header, "std_msgs/msg/Header"),
        }
        topics.update({f"/{c}/features": (ImageFeatures, "awalker_msgs/msg/ImageFeatures") for c in names})
        recorder_node = AwalkerNode("awalker_track_recorder", context=context, **node_options())
        nodes.append(recorder_node)
        recorder = Recorder(recorder_node, result_bag, topics, options.storage)
        executor = SingleThreadedExecutor(context=context)
        for n in nodes:
            if n not in features:
                executor.add_node(n)
        feature_thread = _SpinThread(SingleThreadedExecutor(context=context), features, "awalker_features")
        # every reader is in this process: start once they have matched, with no settle time
        replayer = Replayer(driver, bag, ReplayConfig(lockstep=True, wait_for_subscribers=10.0,
                                                        ack_timeout=ACK_TIMEOUT_S, frames_ahead=FRAMES_AHEAD,
                                                        sync_tolerance=options.sync_tolerance),
                            local_nodes=nodes, reader=reader.reader)
        last = streaming = time.monotonic()
        enough = False          # options.stop_after_frames filtered: the replay is stopped on purpose
        try:
            while replayer.step():
                executor.spin_once(timeout_sec=replayer.next_wait())
                feature_thread.check()
                if why := _undecodable_camera(features, at_end=False):
                    raise InputError(f"{bag}: {why}")
                if options.stop_after_frames and tracker.stats.frames_tracked >= options.stop_after_frames:
                    enough = True
                    break
                if stop.signum is not None:
                    break
                if time.monotonic() - last > PROGRESS_PERIOD_S:
                    last = time.monotonic()
                    done = tracker.stats.frames_received
                    rate = tracker.stats.frames_tracked / max(tracker.stats.seconds_in_filter, 1e-9)
                    _progress(options, f"  frame {done}/{num_frames}, {tracker.stats.summaries} posteriors, "
                                       f"filter {rate:.1f} frames/s")
        finally:
            replayer.close()
        interrupted = stop.signum is not None      # (the frames in work are still taken, then the outputs written)
        feature_thread.check()
        if why := _undecodable_camera(features, at_end=True):
            raise InputError(f"{bag}: {why}")
        if replayer.summary.stopped and not enough and not interrupted:
            raise InputError(f"{bag}: replay stopped: {replayer.summary.stopped}")
        tracker.flush()
        # let the pose publisher and the recorder receive everything published so far
        deadline = time.monotonic() + RECORD_WAIT_S
        # (and every camera's features of the frames the tracker took: the leg fit reads them from result.bag)
        per_posterior = ("/awalker/posterior", "/awalker/joint_states", "/awalker/markers", "/awalker/particles")
        features_topics = [f"/{c}/features" for c in names]

        def short(topics: Sequence[str], expected: int) -> list[str]:
            """'topic count' for each of ``topics`` recorded fewer than ``expected`` times."""
            return [f"{t} {recorder.counts[t]}" for t in topics if recorder.counts[t] < expected]

        # (topics, how many each should hold, what the run made of them) for the wait and its warnings
        expected = [(per_posterior, tracker.stats.summaries, f"{tracker.stats.summaries} posteriors"),
                    (["/awalker/gait_steps"], tracker.stats.steps,
                     f"the posteriors carried {tracker.stats.steps} gait steps"),
                    (features_topics, tracker.stats.frames_received,
                     f"the tracker took {tracker.stats.frames_received} frames")]
        while time.monotonic() < deadline and any(short(topics, count) for topics, count, _ in expected):
            executor.spin_once(timeout_sec=0.05)
        # poses.csv and summary.csv still hold every frame (from the tracker); the result bag does not
        for topics, count, made in expected:
            if missing := short(topics, count):
                print(f"awalker track: warning: {made}, but {result_bag} recorded only {', '.join(missing)} within "
                      f"{RECORD_WAIT_S:g} s of the last frame", file=sys.stderr, flush=True)
        result.seconds_streaming = time.monotonic() - streaming
        executor.shutdown()
        result.frames = tracker.stats.frames_received
        result.summaries = tracker.stats.summaries
        result.seconds_in_filter = tracker.stats.seconds_in_filter
        result.depth_band_m = tracker.recovery.depth_band_m
        result.sync_issues = list(tracker.stats.sync_issues)
        result.recorded = dict(recorder.counts)
        result.features = {node.camera_name: {"background": node.stats.background_from,
                                              "foreground_labels": node.stats.foreground_from} for node in features}
        result.undecodable = {node.camera_name: node.stats.undecodable for node in features}
        if body is None and tracker.body is not None:
            body = tracker.body
            body_src = f"scaled to the person's height seen in the images (written to {out / BODY_FILE})"
        if tracker.start is not None and tracker.start_found_automatically:
            start_src = f"found automatically at frame {tracker.start.frame} (written to {out / START_FILE})"
        if options.fitted_start is not None and tracker.start is not None and tracker.start.stance_leg is not None \
                and (start is None or start.stance_leg is None):
            start_src += (f"; stance leg {LEG_NAMES[tracker.start.stance_leg]} fitted to the first pass's images "
                          f"({options.fitted_start})")
        if not tracker.summaries:
            if interrupted:
                raise stop.interrupted(f"at frame {result.frames} of {num_frames}, before any frame was tracked")
            if tracker.start is None:
                seen = tracker.autostart_status()
                raise InputError(f"{bag}: no walking person found in {result.frames} frames"
                                 + (f" ({seen})" if seen else "") + " (automatic start: a person wholly in view "
                                 "of a camera, moving steadily for 0.7 s); give a start description with --start")
            raise InputError(f"{bag}: no frame was tracked (frames received: {result.frames}; "
                             f"start frame {tracker.start.frame}); check that the bag has images for every camera")
        # one camera cannot tell the near leg from the far one: unless the start named the standing foot, say
        # that left and right may be swapped (a leg fitted to the images, fitted_start, is evidence, not knowledge)
        sides_known = len(cameras) > 1 or (start is not None and start.stance_leg is not None)
        tracks = [(t, t.map_trajectory()) for t in tracker.all_tracks() if t.completed_frames]
        track, walk = write_outputs(out, [(t.track_id, trajectory) for t, trajectory in tracks], tracker.summaries,
                                    sides_known)
        result.tracks = [track_record(t, trajectory) for t, trajectory in tracks]
    finally:
        if feature_thread is not None:
            feature_thread.stop()
        if recorder is not None:
            recorder.close()
        for n in nodes:
            n.destroy_node()
        context.try_shutdown()
        sys.setswitchinterval(switch_interval)
    result.seconds = time.monotonic() - started
    # pictures after tracking, timed apart: they are not needed to keep up with a camera (none when interrupted)
    if not interrupted:
        evaluation.plot_gait_file(out, track, walk)
    if options.overlays and not interrupted:
        write_overlays(bag, out, cameras[0], body, stop=stop)
    result.seconds_pictures = time.monotonic() - started - result.seconds
    (out / RUN_FILE).write_text(yaml.safe_dump({
        "input": str(bag.resolve()), "start_source": start_src, "body_source": body_src,
        "profile": options.profile, "particles": options.particles, "min_particles": fewest_particles(options),
        "lookahead": options.lookahead,
        "trust": options.trust, "seed": options.seed,
        "likelihood_scale": options.likelihood_scale, "leg_scale_spread": options.leg_scale_spread,
        "pelvis_ceiling": (options.pelvis_ceiling if options.pelvis_ceiling is not None
                           else TrackerConfig().pelvis_ceiling_for(len(cameras))[0]),
        "recovery": options.recovery, "depth_band_m": result.depth_band_m,
        "map_downsample": downsample, "sync_tolerance": options.sync_tolerance,
        **({"stopped_after_frames": options.stop_after_frames} if enough else {}),
        "frames": result.frames, "posteriors": result.summaries, "seconds": round(result.seconds, 3),
        "seconds_streaming": round(result.seconds_streaming, 3), "seconds_pictures": round(result.seconds_pictures, 3),
        "seconds_in_filter": round(result.seconds_in_filter, 3), "sync_issues": result.sync_issues,
        "features": result.features, "recorded": result.recorded, "undecodable_images": result.undecodable,
        "tracks": result.tracks, **({"body_fit": body_fit} if body_fit is not None else {})}, sort_keys=False))
    if interrupted:
        raise stop.interrupted(f"at frame {result.frames} of {num_frames}; poses.csv, summary.csv and gait.csv hold "
                               f"the {result.summaries} frames tracked")
    stop.check("after the last frame; the pictures may be incomplete")
    _progress(options, f"awalker track: {result.summaries} frames tracked in {result.seconds:.1f} s "
                       f"({result.frames_per_second:.2f} frames/s end to end, "
                       f"{result.streaming_frames_per_second:.2f} while streaming, filter "
                       f"{result.summaries / max(result.seconds_in_filter, 1e-9):.2f} frames/s; pictures "
                       f"{result.seconds_pictures:.1f} s more)" + _tracks_note(result.tracks)
                       + _undecodable_note(result.undecodable)
                       + f"; outputs in {out}")
    return result


def track_record(tracker: Any, trajectory: Any) -> dict[str, object]:
    """run.yaml's entry for one track (an ``inference.filter_model.Tracker`` and its ``MapTrajectory``): its first
    and last frame, the frames the person was in view, and how it ended: where the person left (frame, reason, last
    frame in view), or ``ended: null``, tracked to the end of the input; the frames at which the posterior renamed
    the legs (``legs_renamed_at``, the naming test)."""
    frames, end = trajectory.frames, tracker.ended
    return {"track": tracker.track_id, "first_frame": int(frames[0]), "last_frame": int(frames[-1]),
            "frames_in_view": int(np.sum(trajectory.in_view)),
            "legs_renamed_at": [int(f) for f in tracker.renamed_frames],
            "ended": None if end is None else {"frame": end.frame_index, "reason": end.reason,
                                               "last_in_view_frame": end.last_in_view_frame}}


def _tracks_note(tracks: list[dict[str, object]]) -> str:
    """'; N tracks (track 1 frames a-b, the person left the view of every camera at frame c; ...)' for the final
    line when a track ended, or ''."""
    if not any(t["ended"] for t in tracks):
        return ""
    parts = [f"track {t['track']} frames {t['first_frame']}-{t['last_frame']}"
             + (f", ended: the person {t['ended']['reason']}" if t["ended"] else "") for t in tracks]
    return f"; {len(tracks)} track{'s' if len(tracks) > 1 else ''} ({'; '.join(parts)})"


def _undecodable_note(undecodable: dict[str, int]) -> str:
    """'; N undecodable images tracked without (cam0 N, ...)' for the final line, or '' when none."""
    if not (total := sum(undecodable.values())):
        return ""
    return (f"; {total} undecodable image{'s' if total > 1 else ''} tracked without ("
            + ", ".join(f"{cam} {n}" for cam, n in undecodable.items() if n) + ")")


def write_outputs(out: Path, trajectories: Sequence[Any], summaries: list[Any],
                  sides_known: bool = True) -> tuple[evaluation.PoseTrack, list]:
    """poses.csv (the MAP trajectories of the run's tracks, one after the other), summary.csv (per-frame posterior
    summaries) and the gait analytics of the MAP trajectories: gait.csv (one row per step seen) and gait.json
    (``evaluation.write_gait``; ``sides_known`` False: with the note that left and right may be swapped).
    ``trajectories``: (track id, ``MapTrajectory``) per track. Returns the MAP pose track and its steps, for the
    footprint picture (``evaluation.plot_gait_file``)."""
    walks = [evaluation.TrackedWalk(track_id, evaluation.PoseTrack(t.frames, t.stamps_ns, tuple(t.marker_names),
                                                                    t.markers), t.stance_leg, t.strike_fraction,
                                    t.in_view) for track_id, t in trajectories]
    track = evaluation.PoseTrack(np.concatenate([w.poses.frames for w in walks]),
                                 np.concatenate([w.poses.stamps_ns for w in walks]), walks[0].poses.marker_names,
                                 np.concatenate([w.poses.markers for w in walks]))
    evaluation.write_poses_csv(out / "poses.csv", track)
    map_leg = {int(s): int(leg) for _, t in trajectories for s, leg in zip(t.stamps_ns, t.stance_leg)}
    map_strike = {int(s): float(f) for _, t in trajectories for s, f in zip(t.stamps_ns, t.strike_fraction)}
    rows = [{"frame": s.frame_index, "stamp_ns": s.stamp_ns, "speed": f"{s.speed:.4f}",
             "speed_std": f"{s.speed_std:.4f}", "stance_left_probability": f"{s.stance_left_probability:.4f}",
             "effective_sample_size": f"{s.effective_sample_size:.1f}", "resampled": int(s.resampled),
             "heel_strike": s.heel_strike_foot,
             "stance_leg": "left" if map_leg.get(s.stamp_ns, s.map_stance_leg) == 0 else "right",
             "reseeded_fallen": s.reseeded_fallen, "reacquired": s.reacquired, "person_still": int(s.person_still),
             "strike_fraction": f"{map_strike.get(s.stamp_ns, float('nan')):.4f}", "track": s.track_id,
             "in_view": int(s.person_in_view), "cameras_in_view": " ".join(s.cameras_in_view),
             "particles": s.num_particles}
            for s in summaries]
    evaluation.write_summary_csv(out / "summary.csv", rows)
    return track, evaluation.write_gait(out, walks, sides_known)


def write_overlays(bag: Path, out: Path, camera: Any, body: BodyDescription, fps: float | None = None,
                   stop: StopRequest | None = None) -> Path | None:
    """Draw the MAP markers on the first camera's frames: overlay/frame_*.png and overlay.mp4 (a frame whose image
    cannot be decoded is left out of both); ``stop``: once a signal set it, no further frames are drawn."""
    import cv2

    from awalker_tools.bagio import SequenceReader
    from awalker_tools.overlay import draw_body
    from awalker_tracker.vision.decode import decode_image

    poses = evaluation.read_poses_csv(out / "poses.csv")
    by_stamp = {int(s): i for i, s in enumerate(poses.stamps_ns)}
    folder = out / "overlay"
    folder.mkdir(exist_ok=True)
    video = None
    path = out / "overlay.mp4"
    with SequenceReader(bag) as reader:
        topic, _ = reader.image_topic_of(camera.name)
        stamps = reader.frame_stamps        # (the first camera's, as ``camera``)
        if fps is None:
            fps = 1e9 / float(np.median(np.diff(stamps))) if len(stamps) > 1 else 30.0
        for _, _, _, msg in reader.messages([topic]):
            if stop is not None and stop.signum is not None:
                break
            try:
                image = decode_image(msg, topic)
            except InputError:
                continue             # counted in run.yaml's undecodable_images
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            if int(stamp) in by_stamp:
                image = draw_body(image, poses.markers[by_stamp[int(stamp)]], camera)
                cv2.imwrite(str(folder / f"frame_{int(poses.frames[by_stamp[int(stamp)]]):05d}.png"), image[..., ::-1])
            if video is None:
                video = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps,
                                        (image.shape[1], image.shape[0]))
            video.write(np.ascontiguousarray(image[..., ::-1]))
    if video is not None:
        video.release()
    return path
