"""Fit the leg length of a tracking run's body, and the stance leg its start left open, to its images
(issue 12 §1, §3; `awalker fitbody DIR`, and `awalker track`'s second pass).

Reads the output directory of a tracking run (the image features it recorded in result.bag, its
calibration.yaml, start.yaml, body.yaml and run.yaml), runs the filter once per candidate leg length
over the first frames from the start (``inference.bodyfit``) and writes DIR/body_fitted.yaml, to track
again with ``awalker track BAG --body DIR/body_fitted.yaml``. A body scaled to the height seen in the
images keeps that height in the fit when two or more cameras saw it (``seen_height_measured``). When the start
names no stance leg (found automatically, or ``stance_leg: unknown``), it then weighs the two legs with the
fitted body the same way and writes DIR/start_fitted.yaml, the start with the leg chosen (``awalker track``
hands it to its second pass's tracker: ``TrackOptions.fitted_start``). Its files follow ``outdir``'s rule: each
is new or one the run's run.yaml lists (checked before the fit), and is added to that list once written.
"""
from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from awalker_tracker.errors import InputError, parse_yaml
from awalker_tracker.inference.sync import DEFAULT_TOLERANCE
from awalker_tracker.model.body import seen_height_measured

from awalker_tools.outdir import RESULT_BAG, add_written, check_may_write

FITTED_FILE = "body_fitted.yaml"
FITTED_START_FILE = "start_fitted.yaml"
# Candidate leg scales by where the run's body came from (run.yaml body_source): a body given (a tape
# measure: the real-walks benchmark's legs 6 % long) or one scaled to the seen height by one camera (the default's
# proportions, ``BodyDescription.from_seen_height``: legs 6-9 % short).
GIVEN_BODY_FACTORS = (0.91, 0.94, 0.97, 1.0, 1.03)
HEIGHT_SCALED_FACTORS = (0.97, 1.0, 1.03, 1.06, 1.09, 1.12)
# ... or scaled to a height two cameras or more measured: a person's proportion of it already (`awalker track`
# fits none, below; these for `awalker fitbody` on its first pass)
MEASURED_HEIGHT_FACTORS = (0.94, 0.97, 1.0, 1.03, 1.06)


def _features(run_dir: Path, cameras: list[Any], tolerance: float) -> tuple[list[int], list[tuple]]:
    """Stamps (ns) and per-frame feature tuples (camera order) recorded in DIR/result.bag, paired as the tracker
    pairs them (``inference.sync``, ``tolerance`` in frame periods); a camera a frame has none of gets features
    carrying no evidence (``vision.features.blank_features``)."""
    from awalker_tools.bagio import iter_messages, open_reader, stamp_ns_of
    from awalker_tools.typestore import typestore
    from awalker_tracker.inference.sync import StampSynchronizer
    from awalker_tracker.nodes.features_node import features_from_msg
    from awalker_tracker.vision.features import blank_features

    bag = run_dir / RESULT_BAG
    camera_names = [c.name for c in cameras]
    topics = {f"/{name}/features": name for name in camera_names}
    store = typestore()
    sync = StampSynchronizer(camera_names, max_pending=1_000_000, tolerance=tolerance)
    frames = []
    reader = open_reader(bag)
    try:
        connections = [c for c in reader.connections if c.topic in topics]
        missing = sorted(set(topics) - {c.topic for c in connections})
        if missing:
            raise InputError(f"{bag}: no {', '.join(missing)} (expected the image features `awalker track` "
                             f"records for cameras {', '.join(camera_names)})")
        for connection, _, raw in iter_messages(reader, bag, connections):
            msg = store.deserialize_cdr(raw, connection.msgtype)
            frames += sync.add(topics[connection.topic], stamp_ns_of(msg.header), features_from_msg(msg))[0]
    finally:
        reader.close()
    frames += sync.flush()[0]
    if len(frames) < 2:
        raise InputError(f"{bag}: {len(frames)} frame(s) with features; at least 2 needed")
    latest: dict[str, Any] = {}
    filled = []
    for frame in frames:
        latest.update({name: item for name, item in zip(camera_names, frame.items) if item is not None})
        like = next(item for item in frame.items if item is not None)
        filled.append(tuple(item if item is not None else blank_features(latest.get(c.name, like), c.width, c.height)
                            for c, item in zip(cameras, frame.items)))
    return [f.stamp_ns for f in frames], filled


def _required(path: Path) -> Path:
    """``path``, which a tracking run's output directory must hold."""
    if not path.is_file():
        raise InputError(f"{path}: not found (expected the output of `awalker track`)")
    return path


def _yaml_file(path: Path) -> dict:
    data = parse_yaml(_required(path).read_text(), str(path))
    if not isinstance(data, dict):
        raise InputError(f"{path}: expected a YAML mapping")
    return data


def fit_run_dir(run_dir: Path, leg_factors: Sequence[float] | None = None,
                check: Callable[[], None] | None = None, **settings: int) -> dict:
    """Fit the leg length of the tracking run in ``run_dir`` (module docstring), write
    ``run_dir/body_fitted.yaml`` and return a summary (factor, leg lengths, evidence, the file written; with
    the stance leg fitted, the leg, each leg's evidence and ``start_written``). ``leg_factors``: the
    candidates; None: by the body's source (``GIVEN_BODY_FACTORS``, ``HEIGHT_SCALED_FACTORS`` or
    ``MEASURED_HEIGHT_FACTORS``); ``(1.0,)``:
    the body as it is (only the stance leg is weighed). ``settings``: the other ``BodyFitConfig`` fields
    (frames, particles, seed, stance_repeats, stance_max_repeats); ``check``: called before each frame of each
    candidate filter, it may raise to stop the fit (`awalker track` stops on a signal). Progress goes to stderr."""
    from awalker_tracker.inference.autostart import AUTO_SPREAD
    from awalker_tracker.inference.bodyfit import BodyFitConfig, fit_leg_length, fit_stance_leg
    from awalker_tracker.inference.filter_model import ImageObservation, StartDescription, TrackerConfig, image_likelihood
    from awalker_tracker.inference.recovery import RecoveryConfig
    from awalker_tracker.inference.smc import SMCConfig
    from awalker_tracker.model.body import BodyDescription
    from awalker_tracker.model.walker import LEG_NAMES
    from awalker_tracker.vision.camera import load_calibration
    from awalker_tracker.vision.features import FeatureConfig
    from awalker_tracker.vision.likelihood import LikelihoodConfig

    if not run_dir.is_dir():
        raise InputError(f"{run_dir}: not a directory (expected the --out DIR of `awalker track`)")
    info = _yaml_file(run_dir / "run.yaml")
    for name in ("calibration.yaml", "start.yaml", "body.yaml"):
        _required(run_dir / name)
    cameras = load_calibration(run_dir / "calibration.yaml")
    scaled = str(info.get("body_source", "")).startswith("scaled to the person's height")
    # a seen height the cameras measured: the candidates keep it, torso and head giving what the legs gain (one
    # camera makes it from the depth it estimates: the legs are added to it)
    measured = scaled and seen_height_measured(len(cameras))
    if leg_factors is None:
        leg_factors = MEASURED_HEIGHT_FACTORS if measured else HEIGHT_SCALED_FACTORS if scaled else GIVEN_BODY_FACTORS
    try:
        fit_config = BodyFitConfig(leg_factors=tuple(leg_factors), keep_height=measured, **settings)
    except ValueError as exc:
        raise InputError(f"fitbody options: {exc}") from None
    start = StartDescription.from_yaml(run_dir / "start.yaml")
    body = BodyDescription.from_yaml(run_dir / "body.yaml")
    # never over a file the run did not write (outdir's rule), checked before the fit's minutes of work
    check_may_write(run_dir, [FITTED_FILE] + ([FITTED_START_FILE] if start.stance_leg is None else []))
    stamps, features = _features(run_dir, cameras, float(info.get("sync_tolerance", DEFAULT_TOLERANCE)))
    dt = float(np.median(np.diff(stamps))) * 1e-9
    first = start.frame
    if first >= len(features) - 1:
        raise InputError(f"{run_dir / 'start.yaml'}: start frame {first}, but result.bag has features for "
                         f"{len(features)} frames")
    auto = str(info.get("start_source", "")).startswith("found automatically")
    # the run's settings (run.yaml), so that each candidate is tracked as the run was, but for the pelvis ceiling:
    # the legs are weighed with the pelvis at the walker's hip (1: off). With the ceiling the evidence favours legs
    # as much longer as it lowers the pelvis, which undoes it (real walks hands off, two cameras: leg factors 1.12
    # against 1.06-1.09 and the pelvis +63 mm high against +20-42; docs/design.md, "Pelvis ceiling")
    recovery = bool(info.get("recovery", True))
    config = TrackerConfig(
        smc=SMCConfig(lookahead=int(info.get("lookahead", 3)), trust=float(info.get("trust", 0.9))),
        dt=dt, likelihood_scale=float(info.get("likelihood_scale", 0.1)), pelvis_ceiling=1.0,
        spread=AUTO_SPREAD if auto else TrackerConfig.spread,
        recovery=RecoveryConfig(reseed_fallen=recovery, reacquire=recovery, hold_still=recovery))
    likelihood = LikelihoodConfig(head_top_weight=1.0)
    observations = [ImageObservation(features=f) for f in features[first:]]
    frames = min(fit_config.frames, len(observations))
    likelihood_for = lambda b: image_likelihood(b, cameras, likelihood)   # noqa: E731
    report = lambda m: print(f"  {m}", file=sys.stderr)                   # noqa: E731
    if tuple(fit_config.leg_factors) == (1.0,):
        summary = {"leg_factor": 1.0, "leg_length_m": round(body.leg_length, 4)}
        fitted_body = body
    else:
        print(f"awalker fitbody: {len(fit_config.leg_factors)} leg lengths x {frames} frames from frame {first}, "
              f"{fit_config.particles} particles each", file=sys.stderr)
        finer = sorted({f.downsample for frame in features for f in frame if f.downsample < FeatureConfig.downsample})
        if finer:
            print(f"awalker fitbody: note: {run_dir / 'result.bag'} holds maps of {finer[0]} x {finer[0]} image pixels "
                  f"each (two cameras or more, vision.features.map_downsample); the leg fit was measured on "
                  f"{FeatureConfig.downsample} x {FeatureConfig.downsample}, and chose longer legs on finer maps. "
                  f"`awalker track --fit-body` fits on a first pass with {FeatureConfig.downsample} x "
                  f"{FeatureConfig.downsample} maps", file=sys.stderr)
        fit = fit_leg_length(body, start, likelihood_for, observations, config, fit_config, cameras=cameras,
                             progress=report, check=check)
        fitted_body = fit.body
        summary = {"leg_factor": fit.factor, "leg_length_m": round(fitted_body.leg_length, 4),
                   "height_kept": fit_config.keep_height,
                   "log_evidence": {f"{k:.2f}": round(v, 2) for k, v in fit.log_evidence.items()}}
    out = run_dir / FITTED_FILE
    out.write_text(fitted_body.to_yaml_text())
    add_written(run_dir, [FITTED_FILE])
    summary.update({"given_leg_length_m": round(body.leg_length, 4), "frames": frames, "written": str(out)})
    if start.stance_leg is None:
        print(f"awalker fitbody: the start names no stance leg; both legs x {frames} frames from frame {first}, "
              f"{fit_config.stance_repeats} filters of {fit_config.particles} particles each (up to "
              f"{fit_config.stance_max_repeats} while the legs lie within {fit_config.stance_tie_nats:g} nats)",
              file=sys.stderr)
        stance = fit_stance_leg(fitted_body, start, likelihood_for, observations, config, fit_config,
                                cameras=cameras, progress=report, check=check)
        fitted_start = replace(start, stance_leg=stance.leg)
        start_out = run_dir / FITTED_START_FILE
        start_out.write_text(fitted_start.to_yaml_text())
        add_written(run_dir, [FITTED_START_FILE])
        summary.update({"stance_leg": LEG_NAMES[stance.leg],
                        "stance_log_evidence": {LEG_NAMES[k]: round(v, 2) for k, v in stance.log_evidence.items()},
                        "stance_filters_per_leg": stance.filters,
                        "start_written": str(start_out)})
    return summary

