"""The composed tracking model and the online tracker (paper Sec. 4-5).

State of one particle: walker state d_t (phi1, phi2, rates, contact origin, stance leg), control
statistics (stiffness, Rao-Blackwellised stiffness mean, toe-off impulse), kinematic DOFs k_t,
plus the posed body and a stride-averaged speed (both derived, kept for the likelihood and
summaries). Transition (eq. 8): stochastic walker dynamics with control, then conditional
kinematics, then the body pose. Likelihood: any function of (previous states, states,
observation); the image likelihood of ``vision.likelihood`` in the pipeline, a marker
likelihood in tests.

Initialisation (paper Sec. 6: "sampled with a large variance about" a coarse hand-set state):
from a ``StartDescription`` (ground position under the pelvis, heading, speed, step length,
stance leg) each particle gets a speed and step length around the given ones, the cyclic
gait of that speed and step length from the gait table, a random phase within the step (the
gait is simulated forward 0..K-1 frames, K = frames per step), then its kinematics around the
start position and heading.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields, is_dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml
from scipy.special import logsumexp

from awalker_tracker.errors import InputError, read_text_file
from awalker_tracker.inference.gait_events import LineageSteps, Step
from awalker_tracker.inference.posterior import ParticleOutputs, PosteriorSummary, summarize
from awalker_tracker.inference.recovery import (
    HELD, REACQUIRED, RESEEDED_FALLEN, LostTrackMonitor, RecoveryConfig, put_rows)
from awalker_tracker.inference.smc import AncestryHistory, FilterStep, ParticleFilter, SMCConfig
from awalker_tracker.inference.speed import SPEED_TIME_CONSTANT_S, update_speed
from awalker_tracker.inference.visibility import TrackEnd, ViewConfig, ViewMonitor, camera_views
from awalker_tracker.model.body import JOINT_NAMES, MARKER_NAMES, BodyDescription, BodyPoseBatch
from awalker_tracker.model.control import STIFFNESS_TARGETS
from awalker_tracker.model.walker import LEFT, LEG_NAMES, RIGHT, WalkerParams, WalkerState

if TYPE_CHECKING:
    from awalker_tracker.vision.likelihood import LikelihoodConfig


# ----------------------------------------------------------------------------- start description


#: Ranges of a start description a person can have: m/s, m (a step), m from the world origin.
START_MAX_SPEED = 3.0
START_STEP_RANGE = (0.1, 1.5)
START_MAX_DISTANCE = 1000.0


@dataclass(frozen=True)
class StartDescription:
    """Coarse initial state (YAML ``start:`` mapping): frame index, ground xy under the pelvis (m),
    heading (rad, walking direction from world +x about +z), speed (m/s), optional step length (m;
    None: the usual step length at that speed, ``step_length_for``), stance leg (LEFT, RIGHT or None:
    unknown, ``unknown`` or omitted in YAML; the particles then start on either leg, half each).

    ``frame`` is the index, counted from 0 at the bag's first frame, of the first frame the
    tracker uses (the person is in view); the frames before it are background-only and teach the
    background model."""

    frame: int = 0
    position: tuple[float, float] = (0.0, 0.0)
    heading: float = 0.0
    speed: float = 1.3
    step_length: float | None = None
    stance_leg: int | None = LEFT

    def step_length_for(self, params: WalkerParams) -> float:
        """The given step length, else a person's usual one at ``speed`` for this leg length (m)."""
        from awalker_tracker.model.cyclic_gaits import preferred_step_length

        return float(self.step_length) if self.step_length is not None else float(
            preferred_step_length(params, self.speed))

    @classmethod
    def from_yaml_text(cls, text: str, where: str = "start description") -> "StartDescription":
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise InputError(f"{where}: not valid YAML ({exc})") from None
        if not isinstance(data, dict) or not isinstance(data.get("start"), dict):
            raise InputError(f"{where}: expected a top-level 'start:' mapping with frame, position [x, y], "
                             "heading (rad), speed (m/s) and optionally step_length (m), stance_leg (left|right|unknown)")
        s = data["start"]
        known = {"frame", "position", "heading", "speed", "step_length", "stance_leg"}
        unknown = sorted(set(s) - known)
        if unknown:
            raise InputError(f"{where}: unknown start field(s) {', '.join(unknown)}; expected {sorted(known)}")
        missing = sorted({"position", "heading", "speed"} - set(s))
        if missing:
            raise InputError(f"{where}: start is missing {', '.join(missing)}")
        try:
            position = tuple(float(v) for v in s["position"])
            frame, heading, speed = int(s.get("frame", 0)), float(s["heading"]), float(s["speed"])
            step_length = None if s.get("step_length") is None else float(s["step_length"])
        except (TypeError, ValueError):
            raise InputError(f"{where}: start values must be numbers (position a list of two), got {s}") from None
        values = [*position, heading, speed] + ([] if step_length is None else [step_length])
        if len(position) != 2 or not np.all(np.isfinite(values)):
            raise InputError(f"{where}: start.position must be [x, y] and all values finite, got {s}")
        if frame < 0 or speed <= 0 or (step_length is not None and step_length <= 0):
            raise InputError(f"{where}: start.frame must be >= 0, speed and step_length > 0, got {s}")
        if not 0 < speed <= START_MAX_SPEED:
            raise InputError(f"{where}: start.speed {speed:g} m/s: expected a walking speed, 0-{START_MAX_SPEED:g} m/s")
        if step_length is not None and not START_STEP_RANGE[0] <= step_length <= START_STEP_RANGE[1]:
            raise InputError(f"{where}: start.step_length {step_length:g} m: expected a person's step, "
                             f"{START_STEP_RANGE[0]:g}-{START_STEP_RANGE[1]:g} m")
        if max(abs(v) for v in position) > START_MAX_DISTANCE:
            raise InputError(f"{where}: start.position {list(position)}: expected within {START_MAX_DISTANCE:g} m "
                             "of the world origin (the cameras' frame)")
        leg = str(s.get("stance_leg") or "unknown").lower()
        if leg not in ("left", "right", "unknown"):
            raise InputError(f"{where}: start.stance_leg must be 'left', 'right' or 'unknown', "
                             f"got {s['stance_leg']!r}")
        if "frame" not in s:
            raise InputError(f"{where}: start is missing frame (the first frame with the person in view; the "
                             "frames before it are background only)")
        return cls(frame, position, heading, speed, step_length, {name: side for side, name in LEG_NAMES.items()}.get(leg))

    @classmethod
    def from_yaml(cls, path: str | Path) -> "StartDescription":
        path = Path(path)
        return cls.from_yaml_text(read_text_file(path, "start description"), str(path))

    def to_yaml_text(self) -> str:
        start = {"frame": self.frame, "position": [float(v) for v in self.position], "heading": float(self.heading),
                 "speed": float(self.speed)}
        if self.step_length is not None:
            start["step_length"] = float(self.step_length)
        start["stance_leg"] = LEG_NAMES.get(self.stance_leg, "unknown")
        return yaml.safe_dump({"start": start}, sort_keys=False)


# ----------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class InitialSpread:
    """Spread of the initial particles around the start description (standard deviations)."""

    position_m: float = 0.10
    heading_rad: float = 0.10
    speed_fraction: float = 0.15       # relative to the start speed
    step_length_fraction: float = 0.10
    joint_rad: float = 0.05
    random_phase: bool = True          # uniform phase within the first step
    # share of the named stance leg's step the phase is drawn from (its last part): a start names the foot
    # the walker stands on, at a double support the trailing one (the walker changes stance at its toe-off)
    named_leg_phase_share: float = 0.75


@dataclass(frozen=True)
class TrackerConfig:
    """Tracker settings: filter (N, tau, gamma, seed), frame period dt (s), initial spread."""

    smc: SMCConfig = SMCConfig()
    dt: float = 1.0 / 30.0
    spread: InitialSpread = InitialSpread()
    speed_time_constant_s: float = SPEED_TIME_CONSTANT_S   # walking speed averaged over about one step (inference.speed)
    fallen_log_penalty: float = 1.0e3    # log-likelihood removed from fallen walkers
    # sigma_kappa_bar^2 of the control prior while tracking (N m/rad per kg)^2. The prior's default (0.01)
    # keeps > 95 % of sampled walkers on their feet for 20 steps (0.02: ~95 % at 5 km/h); real gaits change
    # more from stride to stride (CMU 07_01, bench_accuracy --quick, tracker seeds 0-2: relative error
    # 70/60/52 mm at 0.01, 57/52/47 at 0.02, 53/50/48 at 0.05), and walkers that trip are dropped by the
    # filter (fallen_log_penalty). At 0.05 the filter lost a 600-particle marker track
    # (test_filter_model.py), so 0.02.
    kappa_bar_variance: float = 0.02
    # sigma_tau^2 of each stride's stiffness tilt while tracking (control.ControlPrior.stiffness_tilt_variance),
    # with stiffness_tilt_min_cameras cameras or more; without it the toe-off rule only ever shortens the walker's
    # step (docs/design.md, *Step length*). Not with one camera: a step free to lengthen frees the speed along the
    # view, which one camera hardly sees (docs/tracking.md, *The step's length*)
    stiffness_tilt_variance: float = 0.001
    stiffness_tilt_min_cameras: int = 2
    # What eq. (5) pulls each stride's mean stiffness towards: "constant" mu_kappa (the paper; a slow walker is
    # then held at a 5 km/h cadence, in short quick steps); "usual_gait" (control.ControlPrior.stiffness_target):
    # the cyclic gait's stiffness at the posterior's walking speed and a person's usual step length there (the
    # walker's speed feeds back: a walker fallen behind pulls itself slower); "seen_gait": the same at the speed
    # the images' ground track moves over seen_speed_window_s (s; RecoveryConfig's detections, which the walker
    # does not move), the posterior's speed where the images give none yet; with no lost-track monitor (no
    # cameras, recovery off), the constant (docs/tracking.md, *The gait's pull*)
    stiffness_target: str = "seen_gait"
    seen_speed_window_s: float = 1.0
    # the histogram bins of the adaptive particle count (SMCConfig.min_particles; ``TrackerModel.bin_keys``): the
    # pelvis's ground position (m), the heading (rad) and the walker's stance angle (rad), per stance leg
    count_bins: tuple[float, float, float] = (0.02, 0.05, 0.02)
    # Exponent on the likelihood (tempering). The per-part image log-likelihoods are sums over
    # strongly correlated pixels, so differences between particles of tens of log units are not
    # independent evidence; at 1.0 the weights collapse onto a few particles every frame (ESS 4-9
    # of 500) and the filter loses diversity. Measured on six synthetic sequences (500 particles):
    # relative error 200-250 mm at 1.0, 25-60 mm at 0.03-0.1; with the stable control prior and 5000
    # particles (bench_accuracy): two cameras 382 mm absolute at 1.0, 38-40 mm at 0.1-0.3.
    # 0: the images are not used (dead reckoning: the motion prior alone, fallen walkers still dropped).
    # A tiny positive scale is not the same: the weights then still rank the particles by the images,
    # and the MAP lineage is the best prior walk by image evidence.
    likelihood_scale: float = 0.1
    recovery: RecoveryConfig = RecoveryConfig()
    view: ViewConfig = ViewConfig()      # when the person counts as in view, and the track ends (inference.visibility)
    # how long (s) the MAP lineage carries a heel strike before the live steps (PosteriorSummary.steps,
    # /awalker/gait_steps) take it: the lineage that far back is mostly the one the track ends with
    # (Tracker.lineage_steps)
    step_lag_s: float = 1.0
    cloud_size: int = 200
    # Leg lengths the filter explores (docs/design.md, *Leg length per particle*; off by default): with
    # leg_scale_spread > 0 each particle's thigh and shank are x its own factor, log-normal with this spread
    # when drawn (start, re-seeds), wandering by leg_scale_drift per frame (log, std). Real walks, hand-started,
    # tracker seeds 0-4, 0.04 and 0.001 (bench_realwalks --leg-scale-spread 0.04): medians of the
    # walk medians one camera 125 -> 95 mm (better on 9 of 12 walks), two cameras 88 -> 82 (7 of 12), but per
    # run the change is -7 mm (mean; one camera: 10th-90th percentile -75..+53 mm) and 0 (two cameras), the
    # worst runs are worse (226 -> 328 mm, 138 -> 161) and 54 of 60 one-camera runs end on the person
    # (56): runs whose legs settle below 0.95 gain most (two cameras, seeds 0-2: 74 against 85 mm), runs whose
    # legs grow past 0.99 lose (119 against 95); capped at 1.02, one camera gave 119 mm and two cameras 83.5.
    # docs/design.md, "Leg length per particle".
    leg_scale_spread: float = 0.0
    leg_scale_drift: float = 0.001
    # Postures the filter explores (docs/design.md, *Posture*), with at least posture_min_cameras
    # cameras: each particle's torso pitch rests at its own angle, Table 1's rest (upright) plus
    # N(0, posture_spread^2) rad when drawn (start, re-seeds), wandering by posture_drift rad per frame (std);
    # otherwise, and with posture_spread 0, upright for every particle. Real walks, hand-started, tracker seeds
    # 0-4 (bench_realwalks; docs/design.md, "Posture"): two cameras a median 4.6 mm better per run (42 of 60 runs
    # better; median of the walk medians 64.1 -> 59.2 mm); one camera 17.7 mm worse per run (the body then
    # stands farther from the camera), so one camera keeps Table 1's upright torso.
    posture_spread: float = 0.08
    posture_drift: float = 0.002
    posture_min_cameras: int = 2
    # Pelvis ceilings the filter explores (docs/design.md, *Pelvis ceiling*), with at least
    # pelvis_ceiling_min_cameras cameras: each particle's pelvis stays at most its own fraction of the walker's
    # hip height, pelvis_ceiling plus N(0, pelvis_ceiling_spread^2) when drawn (start, re-seeds) within 0.85-1,
    # wandering by pelvis_ceiling_drift per frame (std); with fewer cameras, or pelvis_ceiling 1, off (the
    # walker's hip height). People walk on a stance knee bent ~20 degrees, the pelvis ~0.96 of the standing leg
    # (docs/design.md, "Pelvis ceiling"). Real walks, two cameras, tracker seeds 0-4, one ceiling of 0.97 for every
    # particle: hand-started the pelvis +37 -> +17 mm high and the median of the walk medians 56.1 -> 53.5 mm
    # (39 of 60 runs better), but our own straight walk (walker renders, pelvis at the hip) 29 -> 39 mm, which
    # the spread lets the images choose; one camera 73.5 -> 79.7 (seeds 0-2: the depth moves with the shape).
    pelvis_ceiling: float = 0.97
    pelvis_ceiling_spread: float = 0.02
    pelvis_ceiling_drift: float = 0.002
    pelvis_ceiling_min_cameras: int = 2
    # A bent knee lowers the hip straight down over the ankle (``KinematicConfig.hip_over_ankle``) with at least
    # hip_over_ankle_min_cameras cameras, and wherever the pelvis ceilings are on (a ceiling bending the stance
    # knee slid the hip back along the walk without it). docs/design.md, "The hip comes down over the ankle": two
    # cameras, hand-started, 54.2 -> 51.9 mm (per run -2.2, 39 of 60 runs better); hands off (after a leg fit,
    # no ceilings) 63.1 -> 61.4 (per run -0.8, within noise, 33 of 60); one camera 73.5 -> 75.9 and worst runs
    # 88-100 mm (seeds 0-2), so one camera keeps the chord's angle.
    hip_over_ankle_min_cameras: int = 2
    # Which leg is which (kinematics.mirrored_legs): seen from one side the near and the far leg look alike, so
    # each particle names its legs the other way round at this rate (per second, a Poisson process): both namings
    # stay in the posterior until the images tell them apart, and a wrong one is replaced when they do; the MAP
    # trajectory names its whole lineage as it ends (``relabel_lineage``). 0: each particle keeps its naming.
    label_flip_rate_hz: float = 0.0
    # Which naming the whole posterior holds (docs/tracking.md, *Which leg is which*): each frame the
    # naming_test_particles highest-weight particles are scored as they are and as their own mirror images (legs
    # named the other way round, parents too, for the flow), and the log odds of the other naming
    # (sum over frames of log sum_k w_k p(z | mirrored s_k) - log sum_k w_k p(z | s_k), tempered, kept at
    # -naming_switch_nats or above) add up; past naming_switch_nats every particle renames its legs and the odds
    # start again from -naming_switch_nats. One particle renaming itself (label_flip_rate_hz) is lost to
    # resampling before its evidence adds up. Tuning subjects, one camera, hand-started, seeds 0-1 (22 runs):
    # at 10 nats 2 runs better (241 -> 217, 148 -> 118 mm), none worse; at 3 nats 5 better and 6 worse (134 -> 149 mm
    # median of the walk medians): a few frames' evidence renamed walkers whose trouble was their step rate.
    # 0 particles: off.
    naming_test_particles: int = 256
    naming_switch_nats: float = 10.0
    # While the person stands still (RecoveryConfig.hold_still) the walkers are held where they stand and may turn
    # there (TrackerModel._turned_in_place): each one's turn rate (rad/s) persists by this factor per frame and
    # wanders by this standard deviation (rad/s per frame); (0.95, 0.35): a stationary spread of ~64 deg/s, so a
    # person turning round on the spot in 2-3 s is within reach. sigma 0: held walkers keep their heading.
    held_turn: tuple[float, float] = (0.95, 0.35)
    # ... and may shift where they stand (a person shuffling as they turn on the spot, or moving slower than
    # RecoveryConfig.still_m_s): each one's ground velocity (m/s, 0 when the hold begins) persists by this factor
    # per frame and wanders by this standard deviation per axis (m/s per frame), at most RecoveryConfig.still_m_s.
    # sigma 0 (the default): held walkers stay where they stand. At (0.95, 0.03) the held frames' error fell on
    # the tuning subjects' walks with stops but the walks after them swapped the legs more often (docs/tracking.md,
    # "Alternatives measured and not used").
    held_drift: tuple[float, float] = (0.95, 0.0)
    # ... and follow where cameras at different angles place the person (LostTrackMonitor.placed_position): each
    # frame every held walker takes the same ground step, which closes the gap between the weighted mean pelvis and
    # that place, less held_follow_within_m, at a rate 1 / held_follow_s, at most held_follow_m_s (m/s). A person
    # slows to a stop over steps the walkers do not all slow down for, and shuffles while standing: held where the
    # hold began, subject 91's bodies stood 0.2-0.3 m off. One step for all leaves the walkers' spread, and so their
    # stride phases, as they were (held_drift's own steps made the images choose among them). The gap within
    # held_follow_within_m is left alone: the triangulated place is good to ~0.1 m and a hand start to 0.05, and
    # closing it all moved standing starts off the person. One camera places no one this way. 0 s (the default):
    # off. At 0.3 s the tuning subjects' stops came nearer at no cost, but the reporting walk that turns on the spot
    # went worse in 2 of 3 runs (docs/tracking.md, "A person who stops"), so it stays an option.
    held_follow_s: float = 0.0
    held_follow_m_s: float = 0.3
    held_follow_within_m: float = 0.15
    # ... and are shown standing (kinematics.standing_body): each held frame the body the outputs show (poses.csv,
    # joint states, markers, the posterior's particles) comes dt / held_settle_s further from the walker's stride
    # towards standing with both legs vertical and the pelvis kept over the ground; once the person walks on it
    # returns at the same rate. The likelihood still scores the walkers' own bodies, so the tracking is as without it.
    # 0 s: off.
    held_settle_s: float = 0.0
    # A person who stood for walk_on_min_hold_s or longer may walk on with either foot: at the first frame after such
    # a hold this share of the walkers, drawn at random, walk on with their legs named the other way round
    # (kinematics.mirrored_legs: the other foot steps; a new stride, not a renaming of the frames before), for the
    # images to choose. 0 (the default): the walkers go on with the strides they stopped in.
    walk_on_mirror_fraction: float = 0.0
    walk_on_min_hold_s: float = 0.5
    # ... where the hold began after the track had walked this long (s): a start names the stance leg of the first
    # steps (the user's, or the leg fit's over its first frames), also where the person stood at the start
    walk_on_after_walked_s: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"TrackerConfig.dt must be > 0 s, got {self.dt}")
        if self.stiffness_target not in (*STIFFNESS_TARGETS, "seen_gait"):
            raise ValueError(f"TrackerConfig.stiffness_target must be one of {(*STIFFNESS_TARGETS, 'seen_gait')}, "
                             f"got {self.stiffness_target!r}")
        if not (np.isfinite(self.seen_speed_window_s) and self.seen_speed_window_s > 0):
            raise ValueError(f"TrackerConfig.seen_speed_window_s must be > 0 s, got {self.seen_speed_window_s}")
        if len(self.count_bins) != 3 or not all(np.isfinite(b) and b > 0 for b in self.count_bins):
            raise ValueError(f"TrackerConfig.count_bins must be three sizes > 0 (m, rad, rad), got {self.count_bins}")
        if not (np.isfinite(self.stiffness_tilt_variance) and self.stiffness_tilt_variance >= 0
                and self.stiffness_tilt_min_cameras >= 1):
            raise ValueError(f"TrackerConfig: stiffness_tilt_variance must be >= 0 and stiffness_tilt_min_cameras "
                             f">= 1, got {self.stiffness_tilt_variance}, {self.stiffness_tilt_min_cameras}")
        if not (np.isfinite(self.kappa_bar_variance) and self.kappa_bar_variance > 0):
            raise ValueError(f"TrackerConfig.kappa_bar_variance must be > 0, got {self.kappa_bar_variance}")
        if not (np.isfinite(self.likelihood_scale) and self.likelihood_scale >= 0):
            raise ValueError(f"TrackerConfig.likelihood_scale must be >= 0, got {self.likelihood_scale}")
        if not (0.0 <= self.leg_scale_spread <= 0.2 and 0.0 <= self.leg_scale_drift <= 0.05):
            raise ValueError(f"TrackerConfig: leg_scale_spread must lie in 0-0.2 and leg_scale_drift in 0-0.05, got "
                             f"{self.leg_scale_spread}, {self.leg_scale_drift}")
        if not (0.0 <= self.posture_spread <= 0.3 and 0.0 <= self.posture_drift <= 0.02
                and self.posture_min_cameras >= 1):
            raise ValueError(f"TrackerConfig: posture_spread must lie in 0-0.3 rad, posture_drift in 0-0.02 rad and "
                             f"posture_min_cameras be >= 1, got {self.posture_spread}, {self.posture_drift}, "
                             f"{self.posture_min_cameras}")
        if not (np.isfinite(self.label_flip_rate_hz) and 0.0 <= self.label_flip_rate_hz * self.dt < 0.5):
            raise ValueError(f"TrackerConfig.label_flip_rate_hz must be >= 0 and below half a flip per frame, got "
                             f"{self.label_flip_rate_hz}")
        if self.naming_test_particles < 0 or not (np.isfinite(self.naming_switch_nats) and self.naming_switch_nats > 0):
            raise ValueError(f"TrackerConfig: naming_test_particles must be >= 0 and naming_switch_nats > 0, got "
                             f"{self.naming_test_particles}, {self.naming_switch_nats}")
        if not (np.isfinite(self.held_settle_s) and self.held_settle_s >= 0.0):
            raise ValueError(f"TrackerConfig.held_settle_s must be >= 0 s, got {self.held_settle_s}")
        if not 0.0 <= self.walk_on_mirror_fraction <= 1.0:
            raise ValueError(f"TrackerConfig.walk_on_mirror_fraction must lie in 0-1, got "
                             f"{self.walk_on_mirror_fraction}")
        for name in ("walk_on_min_hold_s", "walk_on_after_walked_s"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0.0):
                raise ValueError(f"TrackerConfig.{name} must be >= 0 s, got {getattr(self, name)}")
        if not (self.held_follow_s >= 0.0 and self.held_follow_m_s >= 0.0 and self.held_follow_within_m >= 0.0):
            raise ValueError(f"TrackerConfig: held_follow_s, held_follow_m_s and held_follow_within_m must be >= 0, "
                             f"got {self.held_follow_s}, {self.held_follow_m_s}, {self.held_follow_within_m}")
        for name in ("held_turn", "held_drift"):
            persistence, sigma = getattr(self, name)
            if not (0.0 <= persistence <= 1.0 and sigma >= 0.0):
                raise ValueError(f"TrackerConfig.{name} must be (persistence in [0, 1], sigma >= 0), "
                                 f"got {getattr(self, name)}")
        if not (np.isfinite(self.step_lag_s) and self.step_lag_s >= 0.0):
            raise ValueError(f"TrackerConfig.step_lag_s must be >= 0 s, got {self.step_lag_s}")
        if self.hip_over_ankle_min_cameras < 1:
            raise ValueError(f"TrackerConfig.hip_over_ankle_min_cameras must be >= 1, got "
                             f"{self.hip_over_ankle_min_cameras}")
        if not (0.0 <= self.pelvis_ceiling_spread <= 0.1 and self.pelvis_ceiling_min_cameras >= 1):
            raise ValueError(f"TrackerConfig: pelvis_ceiling_spread must lie in 0-0.1 and pelvis_ceiling_min_cameras "
                             f"be >= 1, got {self.pelvis_ceiling_spread}, {self.pelvis_ceiling_min_cameras}")
        from awalker_tracker.model.kinematics import KinematicConfig
        # the kinematics' own checks of what it is given
        KinematicConfig(pelvis_ceiling=self.pelvis_ceiling, pelvis_ceiling_drift=self.pelvis_ceiling_drift)

    def pelvis_ceiling_for(self, cameras: int) -> tuple[float, float, float]:
        """(ceiling, spread, drift) of the particles' pelvis ceilings (fractions of the walker's hip height) in a
        run with this many cameras: (1, 0, 0), off, with fewer than ``pelvis_ceiling_min_cameras`` or a ceiling
        of 1."""
        if cameras < self.pelvis_ceiling_min_cameras or self.pelvis_ceiling >= 1.0:
            return 1.0, 0.0, 0.0
        return self.pelvis_ceiling, self.pelvis_ceiling_spread, self.pelvis_ceiling_drift


# ----------------------------------------------------------------------------- particle states


def where_arrays(mask: np.ndarray, new: Any, old: Any) -> Any:
    """Per particle: fields of ``new`` where ``mask`` else of ``old`` (same dataclass type)."""
    if is_dataclass(new):
        return type(new)(**{f.name: where_arrays(mask, getattr(new, f.name), getattr(old, f.name))
                            for f in fields(new)})
    m = mask.reshape(mask.shape + (1,) * (np.ndim(new) - 1))
    return np.where(m, new, old)


@dataclass
class TrackerStates:
    """N particles: walker, control, kinematics, the posed body and derived quantities."""

    walker: WalkerState
    control: Any                  # model.control.ControlState
    kin: Any                      # model.kinematics.KinematicState
    pose: BodyPoseBatch
    speed: np.ndarray             # (N,) walking speed (m/s): pelvis ground speed averaged over ~one step
    fallen: np.ndarray            # (N,) bool, the walker fell at some point (and was not re-seeded)
    reseeded: np.ndarray          # (N,) int8: re-seeded this frame: 0 no, 1 after a fall, 2 at the detected person
    # (N,) row of the states the frame's re-seeding started from whose walk each particle continues (itself,
    # but for a moved copy: the particle it copies; ``smc`` module doc, ``continues``)
    continues: np.ndarray
    # (N, 3) how far the re-seeding moved each particle this frame beyond its walk: pelvis dx, dy (m) and turn
    # (rad) about the vertical through the pelvis; zeros for particles not re-seeded (``smooth_jumps``)
    jump: np.ndarray
    # (N,) bool: the particle's legs were named the other way round this frame (``TrackerConfig.label_flip_rate_hz``)
    flipped: np.ndarray
    # (N, 2) m/s: the ground velocity of a held walker's shuffle (``TrackerConfig.held_drift``); 0 while walking
    held_velocity: np.ndarray
    # (N,) 0-1: how far the body shown in the outputs stands instead of striding (``TrackerConfig.held_settle_s``)
    standing: np.ndarray

    def __len__(self) -> int:
        return len(self.walker)

    def take(self, indices: np.ndarray) -> "TrackerStates":
        pose = BodyPoseBatch(self.pose.markers[indices], self.pose.joint_angles[indices],
                             self.pose.segments.take(indices))
        return TrackerStates(self.walker.take(indices), self.control.take(indices), self.kin.take(indices),
                             pose, self.speed[indices], self.fallen[indices], self.reseeded[indices],
                             np.arange(len(indices)), self.jump[indices], self.flipped[indices],
                             self.held_velocity[indices], self.standing[indices])


LikelihoodFn = Callable[[TrackerStates | None, TrackerStates, Any], np.ndarray]


def pose_jump(before: TrackerStates, after: TrackerStates) -> np.ndarray:
    """(N, 3) how far re-seeding moved each particle from ``before`` to ``after`` (the same rows): pelvis dx, dy
    (m) and the turn of the heading (rad, wrapped to +-pi)."""
    pelvis = MARKER_NAMES.index("pelvis")
    moved = after.pose.markers[:, pelvis, :2] - before.pose.markers[:, pelvis, :2]
    turn = np.angle(np.exp(1j * (after.kin.heading - before.kin.heading)))
    return np.column_stack([moved, turn])


#: A re-seeding's jump is spread over the MAP trajectory's frames before it (``smooth_jumps``) at this speed
#: (m/s), over at least ``JUMP_SPREAD_MIN_S``: the published path then moves no faster than the walk plus this.
JUMP_SPREAD_M_S = 1.0
JUMP_SPREAD_MIN_S = 0.5


def smooth_jumps(markers: np.ndarray, joint_angles: np.ndarray, jumps: np.ndarray, dt: float,
                 joint_names: tuple[str, ...] = JOINT_NAMES) -> tuple[np.ndarray, np.ndarray]:
    """A lineage's markers (F, M, 3) and joint angles (F, J) with each re-seeding's jump (``jumps`` (F, 3): dx,
    dy, turn at the frame it happened) spread over the frames before it: a frame ``k`` s before a jump of
    ``d`` m is moved by ``(1 - k / T) d`` and turned about its pelvis by as much of the turn, over T =
    max(``JUMP_SPREAD_MIN_S``, |d| / ``JUMP_SPREAD_M_S``). The walk the lineage had before a re-acquisition was
    not the person's; spread so, the trajectory reaches the person without teleporting (issue: the MAP path
    stays physically possible). Where the spreads of several jumps overlap, their summed ground shift still
    changes by at most ``JUMP_SPREAD_M_S`` from frame to frame (it reaches back further instead)."""
    frames = len(markers)
    shift = np.zeros((frames, 3))
    for j in np.flatnonzero(np.any(jumps != 0.0, axis=1)):
        spread = max(JUMP_SPREAD_MIN_S, float(np.hypot(*jumps[j, :2])) / JUMP_SPREAD_M_S)
        before = np.arange(j)
        weight = np.clip(1.0 - (j - before) * dt / spread, 0.0, 1.0)
        shift[before] += weight[:, None] * jumps[j]
    if not shift.any():
        return markers, joint_angles
    # backwards from the last frame (no jump after it: shift 0): each frame's ground shift is the next frame's
    # plus the jump made there, moved towards the summed ramps above by at most JUMP_SPREAD_M_S * dt
    limit = JUMP_SPREAD_M_S * dt
    ground = shift[:, :2].copy()
    for f in range(frames - 2, -1, -1):
        reached = ground[f + 1] + jumps[f + 1, :2]
        step = shift[f, :2] - reached
        size = float(np.hypot(*step))
        ground[f] = reached + (step if size <= limit else step * (limit / size))
    shift[:, :2] = ground
    pelvis = markers[:, MARKER_NAMES.index("pelvis"), None, :2]
    c, s = np.cos(shift[:, 2])[:, None], np.sin(shift[:, 2])[:, None]
    d = markers[..., :2] - pelvis
    out = markers.copy()
    out[..., 0] = pelvis[..., 0] + c * d[..., 0] - s * d[..., 1] + shift[:, 0, None]
    out[..., 1] = pelvis[..., 1] + s * d[..., 0] + c * d[..., 1] + shift[:, 1, None]
    angles = joint_angles.copy()
    if "torso_yaw" in joint_names:
        angles[:, joint_names.index("torso_yaw")] += shift[:, 2]
    return out, angles


def _within_length(vectors: np.ndarray, longest: float) -> np.ndarray:
    """``vectors`` (..., 2) each scaled down to at most ``longest`` long (in their own unit: m, m/s); shorter ones
    are returned as they are."""
    length = np.linalg.norm(vectors, axis=-1)
    return vectors * np.minimum(1.0, longest / np.maximum(length, 1e-12))[..., None]


class TrackerModel:
    """SMC model (``initial``, ``transition``, ``log_likelihood``) of the physics-based tracker."""

    def __init__(self, body: BodyDescription, start: StartDescription, likelihood: LikelihoodFn,
                 config: TrackerConfig = TrackerConfig(), params: WalkerParams | None = None,
                 gait_table: Any = None, prior: Any = None, kinematics: Any = None,
                 cameras: list[Any] | None = None) -> None:
        """``cameras``: the image likelihood's cameras, for re-acquiring a lost track (None: no re-acquisition),
        for the postures (``TrackerConfig.posture_min_cameras``), the pelvis ceiling (``pelvis_ceiling_for``),
        eq. (5)'s seen gait (``TrackerConfig.stiffness_target``) and the stiffness tilt
        (``stiffness_tilt_min_cameras``)."""
        from awalker_tracker.model import control, cyclic_gaits, kinematics as kin_mod

        self.body = body
        self.start = start
        self.config = config
        self.likelihood = likelihood
        self.params = params or body.walker_params()
        # the packaged table is solved for L = 0.9 m: rescaled (exactly) to this body's leg length
        self.gaits = (gait_table if gait_table is not None else cyclic_gaits.GaitTable.load()).scaled_to(self.params)
        # rad: the spread of the particles' postures, 0 (upright) with fewer cameras than posture_min_cameras
        self.posture_spread = config.posture_spread if len(cameras or ()) >= config.posture_min_cameras else 0.0
        ceiling, self.pelvis_ceiling_spread, ceiling_drift = config.pelvis_ceiling_for(len(cameras or ()))
        self.kin_config = kinematics if kinematics is not None else kin_mod.KinematicConfig(
            dt=config.dt, leg_scale_drift=config.leg_scale_drift if config.leg_scale_spread > 0 else 0.0,
            posture_drift=config.posture_drift if self.posture_spread > 0 else 0.0,
            pelvis_ceiling=ceiling, pelvis_ceiling_drift=ceiling_drift,
            hip_over_ankle=ceiling < 1.0 or len(cameras or ()) >= config.hip_over_ankle_min_cameras)
        self.cameras = list(cameras or ())
        self._control = control
        self._cyclic_gaits = cyclic_gaits
        self._kin = kin_mod
        self.monitor = (LostTrackMonitor(cameras, config.recovery, config.dt, body_height_m=self.body.height)
                        if cameras and (config.recovery.reacquire or config.recovery.hold_still) else None)
        # eq. (5)'s target as used (TrackerConfig.stiffness_target: "seen_gait" needs the monitor's detections)
        self.stiffness_target = config.stiffness_target
        if config.stiffness_target == "seen_gait" and self.monitor is None:
            self.stiffness_target = "constant"
        self.prior = prior if prior is not None else control.ControlPrior.from_gait_table(
            self.gaits, kappa_bar_variance=config.kappa_bar_variance,
            stiffness_tilt_variance=(config.stiffness_tilt_variance
                                     if len(self.cameras) >= config.stiffness_tilt_min_cameras else 0.0),
            stiffness_target="constant" if self.stiffness_target == "constant" else "usual_gait")
        self.reseeded_fallen = 0     # particles re-seeded after a fall, over the run
        # frame periods the next transition spans (``Tracker.push``: from the stamps; > 1 over frames no image came for)
        self.frames_per_step = 1
        self._depth_band: tuple[np.ndarray, float] | None = None   # this frame's centre and half width, one camera
        self._heading_band: tuple[float, float] | None = None      # this frame's direction and half width, one camera
        self._target_speed = float(start.speed)      # m/s, eq. (5)'s target speed (rejuvenate)
        # the naming test (TrackerConfig.naming_test_particles): log odds of the other naming, each frame's evidence
        # (filter frame index -> nats), the decision taken at each frame (True: every particle renamed its legs
        # there), and what this frame's likelihood call needs (rejuvenate -> log_likelihood)
        self.naming_log_odds = 0.0
        self._naming_evidence: dict[int, float] = {}
        self.naming_decisions: dict[int, bool] = {}
        # rename frame -> the frame since which the evidence favoured the other naming (the last frame whose odds
        # sat at their floor before they rose): where the naming went wrong, e.g. a step the walker took or missed
        self.naming_onsets: dict[int, int] = {}
        self._naming_floor_frame = 0
        self._naming_pending: tuple[int, np.ndarray, TrackerStates, bool] | None = None

    # -- SMC protocol ---------------------------------------------------------------------
    def initial(self, n: int, rng: np.random.Generator) -> TrackerStates:
        s = self.start
        step_length = s.step_length_for(self.params)
        if not self._gait_known(np.array([s.speed]), np.array([step_length]))[0]:
            raise InputError(f"start description: no cyclic gait for speed {s.speed} m/s and step length "
                             f"{step_length:.3f} m in the gait table; give values inside "
                             f"{self.gaits.speeds[0]:.2f}-{self.gaits.speeds[-1]:.2f} m/s, "
                             f"{self.gaits.step_lengths[0]:.2f}-{self.gaits.step_lengths[-1]:.2f} m")
        spread = self.config.spread
        return self._fresh(n, np.asarray(s.position, float), np.full(n, s.heading), np.full(n, s.speed),
                           np.full(n, step_length), self._start_legs(n, rng), rng, spread,
                           phase_share=spread.named_leg_phase_share if s.stance_leg is not None else 1.0)

    def _start_legs(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """(N,) stance legs of the initial particles: the start's, or half each when it is unknown."""
        if self.start.stance_leg is not None:
            return np.full(n, self.start.stance_leg, np.int8)
        return rng.permutation(np.arange(n) % 2).astype(np.int8)

    def _fresh(self, n: int, pelvis_xy: np.ndarray, heading: np.ndarray, speed: np.ndarray, step: np.ndarray,
               stance_leg: np.ndarray, rng: np.random.Generator, spread: InitialSpread,
               phase_share: float = 1.0) -> TrackerStates:
        """N new particles on cyclic gaits around the given speeds and step lengths (per particle),
        pelvis above ``pelvis_xy`` ((2,) or (N, 2), m), walking along ``heading`` (rad), with ``spread``
        (a random phase within the last ``phase_share`` of the step)."""
        speed, step = self._sample_gaits(speed, step, spread, rng)
        walker = self._cyclic_gaits.gait_initial_state(self.params, speed, step, contact_origin=0.0,
                                               stance_leg=stance_leg, table=self.gaits)
        _, _, stiffness, impulse = self.gaits.lookup(speed, step)
        control = self._control.initial_control(self.prior, n, rng, stiffness=np.asarray(stiffness, float),
                                                toe_off_impulse=np.asarray(impulse, float))
        if spread.random_phase:
            walker, control = self._random_phase(walker, control, speed, step, rng, phase_share)
        kin = self._kin.initial_kinematics(
            self.kin_config, walker, pelvis_xy, heading, n, rng, body=self.body,
            params=self.params, position_spread=spread.position_m, heading_spread=spread.heading_rad,
            joint_spread=spread.joint_rad, leg_scale_spread=self.config.leg_scale_spread,
            posture_spread=self.posture_spread, pelvis_ceiling_spread=self.pelvis_ceiling_spread)
        pose = self._kin.pose_body(self.body, self.params, walker, kin, self.kin_config)
        return TrackerStates(walker, control, kin, pose, speed.copy(), np.zeros(n, bool), np.zeros(n, np.int8),
                             np.arange(n), np.zeros((n, 3)), np.zeros(n, bool), np.zeros((n, 2)), np.zeros(n))

    def _gait_known(self, speed: np.ndarray, step: np.ndarray) -> np.ndarray:
        """True where the gait table's lookup has converged corners with weight (a margin above what lookup needs)."""
        return self.gaits.covers(speed, step, min_weight=1e-6)

    def _sample_gaits(self, speed: np.ndarray, step: np.ndarray, spread: InitialSpread,
                      rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Speeds and step lengths drawn around the given ones (per particle, log-normal with the spread's
        fractions), redrawn where the gait table has no gait; where none is found, the given ones (moved
        into the table where they lie outside it)."""
        base_speed, base_step = self._known_gait(np.asarray(speed, float), np.asarray(step, float))
        speed, step = base_speed.copy(), base_step.copy()
        todo = np.ones(speed.size, bool)
        for _ in range(20):
            k = int(todo.sum())
            speed[todo] = base_speed[todo] * np.exp(spread.speed_fraction * rng.standard_normal(k))
            step[todo] = base_step[todo] * np.exp(spread.step_length_fraction * rng.standard_normal(k))
            todo &= ~self._gait_known(speed, step)
            if not todo.any():
                break
        speed[todo], step[todo] = base_speed[todo], base_step[todo]
        return speed, step

    def _known_gait(self, speed: np.ndarray, step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The given gaits where the table knows them; elsewhere the speed clamped into the table and the
        usual step length at that speed (``preferred_step_length``)."""
        known = self._gait_known(speed, step)
        if known.all():
            return speed, step
        speeds = self.gaits.speeds
        clamped = np.clip(speed, speeds[1], speeds[-2])
        usual = np.clip(self._cyclic_gaits.preferred_step_length(self.params, clamped), self.gaits.step_lengths[1],
                        self.gaits.step_lengths[-2])
        return np.where(known, speed, clamped), np.where(known, step, usual)

    def _random_phase(self, walker: WalkerState, control: Any, speed: np.ndarray, step: np.ndarray,
                      rng: np.random.Generator, share: float = 1.0) -> tuple[WalkerState, Any]:
        """Advance each particle by a uniform number of frames within the last ``share`` of its first step."""
        frames_per_step = np.maximum(1, np.floor(step / speed / self.config.dt)).astype(int)
        offsets = (((1.0 - share) + share * rng.random(walker.stance_angle.size)) * frames_per_step).astype(int)
        for j in range(int(offsets.max())):
            moved, moved_control, events = self._control.sample_transition(
                self.params, self.prior, walker, control, self.config.dt, rng, target_speed=self._target_speed)
            # stop before a heel strike or a fall: the start description fixes the stance leg
            stop = np.asarray(events.heel_strike, bool) | np.asarray(events.fallen, bool)
            offsets = np.where(stop, 0, offsets)
            keep = offsets > j
            walker = where_arrays(keep, moved, walker)
            control = where_arrays(keep, moved_control, control)
        return walker, control

    def transition(self, states: TrackerStates, rng: np.random.Generator) -> tuple[TrackerStates, Any]:
        """``frames_per_step`` frames of the dynamics (``_transition_frame``): a gap in the stamps is walked
        through, not skipped; the frames' re-seedings, jumps, label flips and heel strikes are merged (a strike's
        ``strike_fraction`` then a fraction of the whole step, the last strike's)."""
        new, events = self._transition_frame(states, rng)
        k = self.frames_per_step
        if k == 1:
            return new, events
        fraction = np.where(events.heel_strike, events.strike_fraction / k, events.strike_fraction)
        merged = replace(events, heel_strike=events.heel_strike.copy(), fallen=events.fallen.copy(),
                         strike_fraction=fraction, strike_position=events.strike_position.copy(),
                         toe_off_impulse=events.toe_off_impulse.copy(), pre_strike_rates=events.pre_strike_rates.copy())
        for j in range(1, k):
            more, later = self._transition_frame(new, rng)
            new = replace(more, reseeded=np.where(more.reseeded != 0, more.reseeded, new.reseeded),
                          jump=new.jump + more.jump, flipped=new.flipped | more.flipped)
            hit = np.asarray(later.heel_strike, bool)
            merged.heel_strike |= hit
            merged.fallen |= np.asarray(later.fallen, bool)
            merged.strike_fraction[hit] = (j + later.strike_fraction[hit]) / k
            merged.strike_position[hit] = later.strike_position[hit]
            merged.toe_off_impulse[hit] = later.toe_off_impulse[hit]
            merged.pre_strike_rates[hit] = later.pre_strike_rates[hit]
            merged.time_since_strike = later.time_since_strike
        return new, merged

    def _transition_frame(self, states: TrackerStates, rng: np.random.Generator) -> tuple[TrackerStates, Any]:
        """One frame period of the dynamics, s_t ~ p(s_t | s_{t-1})."""
        walker, control, events = self._control.sample_transition(
            self.params, self.prior, states.walker, states.control, self.config.dt, rng,
            target_speed=self._target_speed)
        kin, pose = self._kin.sample_posed_kinematics(self.kin_config, self.body, self.params, walker,
                                                      states.kin, rng)
        # walking speed (inference.speed): horizontal pelvis displacement per frame, averaged over about one step
        pelvis = MARKER_NAMES.index("pelvis")
        moved = np.linalg.norm(pose.markers[:, pelvis, :2] - states.pose.markers[:, pelvis, :2], axis=1)
        fallen = states.fallen | np.asarray(events.fallen, bool)
        # a fall is not walking: a fallen walker keeps its speed (re-seeding starts it on that speed's gait)
        speed = np.where(fallen, states.speed,
                         update_speed(states.speed, moved, self.config.dt, self.config.speed_time_constant_s))
        new = TrackerStates(walker, control, kin, pose, speed, fallen, np.zeros(len(states), np.int8),
                            np.arange(len(states)), np.zeros((len(states), 3)), np.zeros(len(states), bool),
                            np.zeros((len(states), 2)), np.zeros(len(states)))
        if self.config.recovery.reseed_fallen and fallen.any():
            new = self._reseed_fallen(new, np.flatnonzero(fallen), rng)
        if self.config.label_flip_rate_hz > 0:
            new = self._flip_labels(new, np.flatnonzero(rng.random(len(new)) < self.config.label_flip_rate_hz
                                                        * self.config.dt))
        # each particle continues its own walk (the rows put above came with their own, meaningless here)
        return replace(new, continues=np.arange(len(new))), events

    def _flip_labels(self, states: TrackerStates, rows: np.ndarray) -> TrackerStates:
        """The particles ``rows`` with their legs named the other way round (``kinematics.mirrored_legs``: each body
        its own mirror image, pelvis kept), each continuing its own lineage (``continues``): the prior's jump between
        the two namings a side view cannot tell apart."""
        if rows.size == 0:
            return states
        flipped = replace(self._mirrored(states.take(rows)), flipped=np.ones(rows.size, bool),
                          continues=states.continues[rows])
        return put_rows(states, rows, flipped)

    def _reseed_fallen(self, states: TrackerStates, rows: np.ndarray, rng: np.random.Generator) -> TrackerStates:
        """Replace fallen walkers by walkers on the cyclic gait of their recent speed, caught by their other leg
        where they fell: the pelvis where it was over the ground, the leg that swung just struck in front (a new
        step on it, no phase spread), walking along their heading. The falls seen in tracking are forwards (the
        stance leg past ``dynamics.MAX_STANCE_LEAN``, the swing leg not yet through); stood over the foot they
        fell over instead, they jumped back 0.5-0.7 m."""
        still = InitialSpread(position_m=0.0, heading_rad=0.0, speed_fraction=0.05, step_length_fraction=0.05,
                              joint_rad=0.02, random_phase=False)
        speed = states.speed[rows]
        pelvis = states.pose.markers[rows, MARKER_NAMES.index("pelvis"), :2]
        fresh = self._fresh(rows.size, pelvis, states.kin.heading[rows], speed,
                            self._cyclic_gaits.preferred_step_length(self.params, speed),
                            (1 - states.walker.stance_leg[rows]).astype(np.int8), rng, still)
        fresh.reseeded[:] = RESEEDED_FALLEN
        fresh.jump[:] = pose_jump(states.take(rows), fresh)
        self.reseeded_fallen += rows.size
        return put_rows(states, rows, fresh)

    def bin_keys(self, states: TrackerStates) -> np.ndarray:
        """(N, 5) int: each particle's histogram bin for the adaptive particle count (``smc`` module doc): its
        pelvis's ground position, heading and stance angle in ``TrackerConfig.count_bins``, and its stance leg."""
        position_m, heading_rad, phase_rad = self.config.count_bins
        pelvis = states.pose.markers[:, MARKER_NAMES.index("pelvis"), :2]
        return np.column_stack([np.floor(pelvis / position_m), np.floor(states.kin.heading / heading_rad),
                                np.floor(states.walker.stance_angle / phase_rad),
                                states.walker.stance_leg]).astype(np.int64)

    def rejuvenate(self, frame: int, log_weights: np.ndarray, parent: TrackerStates | None, states: TrackerStates,
                   obs: Any, rng: np.random.Generator) -> TrackerStates:
        """Called by the filter with the particles' current log weights, the states before the transition
        (``parent``, None at the first frame) and after it, before the likelihood of ``obs`` is computed: the
        recovery (``_recovered``), then the naming test's renaming (``_named``). Also keeps eq. (5)'s target speed
        (``TrackerConfig.stiffness_target``): the posterior's walking speed, or the images' ground track's."""
        w = np.exp(log_weights - np.max(log_weights))
        w /= w.sum()
        self._target_speed = float(w @ states.speed)
        states = self._recovered(frame, log_weights, w, parent, states, obs, rng)
        if self.stiffness_target == "seen_gait" and frame in self.monitor.track.positions:   # it saw this frame
            seen = self.monitor.track.velocity(frame, self.config.seen_speed_window_s)
            if seen is not None:
                self._target_speed = float(np.linalg.norm(seen))
        return self._named(frame, log_weights, parent, states, obs)

    @property
    def target_speed(self) -> float:
        """Eq. (5)'s target speed (m/s) for the next transition's strides (``TrackerConfig.stiffness_target``)."""
        return self._target_speed

    @property
    def renamed_frames(self) -> list[int]:
        """Filter frame indices at which every particle renamed its legs (the naming test)."""
        return sorted(self.naming_onsets)

    def _named(self, frame: int, log_weights: np.ndarray, parent: TrackerStates | None, states: TrackerStates,
               obs: Any) -> TrackerStates:
        """``states`` with every particle's legs renamed where the naming test's log odds passed
        ``naming_switch_nats`` with the evidence up to the frame before (decided when the frame is first simulated,
        kept when the look-ahead simulates it again); sets up this frame's test for ``log_likelihood``."""
        cfg = self.config
        self._naming_pending = None
        if cfg.naming_test_particles <= 0 or parent is None:
            return states
        if frame not in self.naming_decisions:
            odds = max(self.naming_log_odds + self._naming_evidence.pop(frame - 1, 0.0), -cfg.naming_switch_nats)
            renamed = odds > cfg.naming_switch_nats
            if renamed:
                self.naming_onsets[frame] = self._naming_floor_frame
            if renamed or odds <= -cfg.naming_switch_nats:
                self._naming_floor_frame = frame
            self.naming_log_odds = -cfg.naming_switch_nats if renamed else odds
            self.naming_decisions[frame] = renamed
        renamed = self.naming_decisions[frame]
        if renamed:
            states = self._flip_labels(states, np.arange(len(states)))
        self._naming_pending = (frame, log_weights, parent, renamed)
        return states

    def _mirrored(self, states: TrackerStates) -> TrackerStates:
        """Every particle of ``states`` with its legs named the other way round (``kinematics.mirrored_legs``: each
        body its own mirror image, pelvis kept), posed."""
        pelvis = states.pose.markers[:, MARKER_NAMES.index("pelvis"), :2]
        walker, kin = self._kin.mirrored_legs(states.walker, states.kin, pelvis, self.body, self.params, self.kin_config)
        return replace(states, walker=walker, kin=kin,
                       pose=self._kin.pose_body(self.body, self.params, walker, kin, self.kin_config))

    def _shown_standing(self, frame: int, parent: TrackerStates | None, states: TrackerStates) -> TrackerStates:
        """``states`` with how far their bodies are shown standing at ``frame`` (``TrackerConfig.held_settle_s``):
        dt / held_settle_s further than their ``parent``'s (the frame before; every particle alike) while the person
        stands still, as much less after."""
        settle = self.config.held_settle_s
        if settle <= 0:
            return states
        before = float(parent.standing.max()) if parent is not None and len(parent) else 0.0
        step = self.config.dt / settle * (1 if self.monitor.still(frame) else -1)
        amount = float(np.clip(before + step, 0.0, 1.0))
        if amount == 0.0 and not np.any(states.standing > 0.0):
            return states
        return replace(states, standing=np.full(len(states), amount))

    def _naming_evidence_of(self, pending: tuple, loglik: np.ndarray, states: TrackerStates, obs: Any) -> None:
        """This frame's evidence for the other naming (nats, tempered; ``TrackerConfig.naming_test_particles``),
        from the frame's likelihoods ``loglik`` (N,) of ``states`` (``pending``: ``_named``'s frame, log weights,
        parents and renaming): kept per frame, replaced when the frame is
        simulated again before the next frame's decision."""
        frame, log_weights, parent, _ = pending
        if frame + 1 in self.naming_decisions:     # simulated again after the next frame's decision: not needed
            return
        k = min(self.config.naming_test_particles, len(states))
        rows = np.argpartition(-log_weights, k - 1)[:k]
        mirrored = self.likelihood(self._mirrored(parent.take(rows)), self._mirrored(states.take(rows)), obs)
        scale = self.config.likelihood_scale
        w = log_weights[rows]
        self._naming_evidence[frame] = float(logsumexp(w + scale * np.asarray(mirrored, float))
                                             - logsumexp(w + scale * loglik[rows]))

    def _recovered(self, frame: int, log_weights: np.ndarray, w: np.ndarray, parent: TrackerStates | None,
                   states: TrackerStates, obs: Any, rng: np.random.Generator) -> TrackerStates:
        """Hold the walkers while the person stands still and re-acquire a lost track from the image
        (``inference.recovery``); ``w``: the normalised weights of ``log_weights``."""
        self._depth_band = self._heading_band = None
        if self.monitor is None or not isinstance(obs, ImageObservation):
            return states
        return self._shown_standing(frame, parent,
                                    self._held_or_reacquired(frame, log_weights, w, parent, states, obs, rng))

    def _held_or_reacquired(self, frame: int, log_weights: np.ndarray, w: np.ndarray, parent: TrackerStates | None,
                            states: TrackerStates, obs: Any, rng: np.random.Generator) -> TrackerStates:
        """``_recovered``'s holding and re-acquisition."""
        pelvis = w @ states.pose.markers[:, MARKER_NAMES.index("pelvis")]
        order = self.monitor.update(frame, obs.features, pelvis)
        self._depth_band = self.monitor.depth_band(frame)
        self._heading_band = self.monitor.heading_band(frame)
        if parent is not None and self.monitor.still(frame):
            # the person stands still: the frame's walkers are the previous frame's, not walking, but free to
            # turn where they stand (a person turning round on the spot)
            states = replace(self._turned_in_place(parent, rng, self._follow_step(frame, w, parent)),
                             speed=np.zeros(len(parent)),
                             reseeded=np.full(len(parent), HELD, np.int8), continues=np.arange(len(parent)),
                             jump=np.zeros((len(parent), 3)), flipped=np.zeros(len(parent), bool))
        elif parent is not None and self._walks_on_after_hold(frame):
            states = self._stepping_off_either_foot(states, rng)
        if order is None:
            return states
        n = len(states)
        rows = np.argsort(log_weights, kind="stable")[: max(1, int(self.config.recovery.reacquire_fraction * n))]
        r = self.config.recovery
        # half: copies of the current particles (drawn by weight) moved onto the person, keeping their gait
        # phase, stance leg and joints (often still right: a turn or a depth error lost the body, not the
        # step); half: fresh walkers there at any phase
        half = rows.size // 2
        sources = rng.choice(n, size=half, p=w)
        copies = states.take(sources)
        pelvis_xy = copies.pose.markers[:, MARKER_NAMES.index("pelvis"), :2]
        target = order.position + r.position_spread_m * rng.standard_normal((half, 2))
        turn = (np.angle(np.exp(1j * (order.heading - copies.kin.heading))) if order.heading is not None
                else np.zeros(half)) + r.heading_spread_rad * rng.standard_normal(half)
        kin = self._kin.moved_on_ground(copies.kin, pelvis_xy, target, turn)
        moved = replace(copies, kin=kin, pose=self._kin.pose_body(self.body, self.params, copies.walker, kin,
                                                                   self.kin_config),
                        reseeded=np.full(half, REACQUIRED, np.int8))
        # the jump from the walk each continues: a copy of a walker re-seeded after a fall this very frame adds
        # to that re-seeding's jump (dropped, the MAP path kept a 0.6 m step where both came at once)
        moved.jump[:] = copies.jump + pose_jump(copies, moved)
        k = rows.size - half
        # without a ground track long enough: the particles' heading, the start's speed, both spread wide
        heading = order.heading if order.heading is not None else float(np.angle(np.sum(w * np.exp(1j * states.kin.heading))))
        speed = order.speed if order.speed is not None else self.start.speed
        spread = replace(self.config.spread, position_m=r.position_spread_m, heading_rad=r.heading_spread_rad,
                         speed_fraction=max(self.config.spread.speed_fraction, 0.25))
        left = np.sum(w[states.walker.stance_leg == LEFT])
        fresh = self._fresh(k, order.position, np.full(k, heading), np.full(k, speed),
                            self._cyclic_gaits.preferred_step_length(self.params, np.full(k, speed)),
                            np.where(rng.random(k) < left, LEFT, RIGHT).astype(np.int8), rng, spread)
        fresh.reseeded[:] = REACQUIRED
        fresh.jump[:] = states.jump[rows[half:]] + pose_jump(states.take(rows[half:]), fresh)
        states = put_rows(states, rows[:half], moved)
        states = put_rows(states, rows[half:], fresh)
        # a moved copy continues the walk of the particle it copies (its lineage), a fresh walker its row's
        continues = np.arange(n)
        continues[rows[:half]] = sources
        return replace(states, continues=continues)

    def _walks_on_after_hold(self, frame: int) -> bool:
        """Whether ``frame`` is the first after the person stood still for ``walk_on_min_hold_s`` or longer, in a hold
        that began ``walk_on_after_walked_s`` or more after the first frame the monitor saw."""
        cfg = self.config
        if cfg.walk_on_mirror_fraction <= 0 or self.monitor.still(frame) or not self.monitor.still(frame - 1):
            return False
        held = 1
        while self.monitor.still(frame - held - 1):
            held += 1
        walked = frame - held - self.monitor.first_frame
        return held * cfg.dt >= cfg.walk_on_min_hold_s - 1e-9 and walked * cfg.dt >= cfg.walk_on_after_walked_s - 1e-9

    def _stepping_off_either_foot(self, states: TrackerStates, rng: np.random.Generator) -> TrackerStates:
        """``states`` with a random share (``walk_on_mirror_fraction``) of the walkers walking on with their legs named
        the other way round: a new stride on the other foot, not a renaming (the frames before keep their naming)."""
        rows = np.flatnonzero(rng.random(len(states)) < self.config.walk_on_mirror_fraction)
        return replace(self._flip_labels(states, rows), flipped=states.flipped)

    def _follow_step(self, frame: int, w: np.ndarray, held: TrackerStates) -> np.ndarray:
        """The ground step (2,) m every held walker takes at ``frame`` towards where the cameras place the person
        (``TrackerConfig.held_follow_s``): the gap from the weighted (``w``) mean pelvis of ``held``, less
        held_follow_within_m, closed at a rate 1 / held_follow_s, at most held_follow_m_s; zero when off or where no
        place is known."""
        cfg = self.config
        place = self.monitor.placed_position(frame) if cfg.held_follow_s > 0 else None
        if place is None:
            return np.zeros(2)
        gap = place - w @ held.pose.markers[:, MARKER_NAMES.index("pelvis"), :2]
        distance = float(np.linalg.norm(gap))
        if distance <= cfg.held_follow_within_m:
            return np.zeros(2)
        step = gap * (1.0 - cfg.held_follow_within_m / distance) * min(1.0, cfg.dt / cfg.held_follow_s)
        return _within_length(step, cfg.held_follow_m_s * cfg.dt)

    def _turned_in_place(self, states: TrackerStates, rng: np.random.Generator,
                         step: np.ndarray | None = None) -> TrackerStates:
        """Held walkers turned about the vertical through their pelvis at their own turn rate, which wanders
        (``TrackerConfig.held_turn``: omega' = persistence omega + N(0, sigma^2) per frame, |omega| <= the turn
        prior's largest rate): people standing still turn round on the spot, and the walkers that face the
        way the images do are the ones that walk on. With ``TrackerConfig.held_drift`` the pelvis also moves
        at its own wandering ground velocity v' = persistence v + N(0, sigma^2 I) (|v| <= ``still_m_s``), and with
        ``step`` (2,) m all move by that common ground step (``_follow_step``)."""
        persistence, sigma = self.config.held_turn
        drift_persistence, drift_sigma = self.config.held_drift
        step = np.zeros(2) if step is None else np.asarray(step, float)
        if sigma <= 0 and drift_sigma <= 0 and not step.any():
            return states
        n = len(states)
        kin = states.kin.copy()
        if sigma > 0:
            kin.turn_rate = np.clip(persistence * kin.turn_rate + sigma * rng.standard_normal(n),
                                    -self._kin.TurnPrior().max_rate, self._kin.TurnPrior().max_rate)
        velocity = states.held_velocity
        if drift_sigma > 0:
            velocity = _within_length(drift_persistence * velocity + drift_sigma * rng.standard_normal((n, 2)),
                                      self.config.recovery.still_m_s)
        pelvis = states.pose.markers[:, MARKER_NAMES.index("pelvis"), :2]
        turn = kin.turn_rate * self.config.dt if sigma > 0 else np.zeros(n)
        turned = self._kin.moved_on_ground(kin, pelvis, pelvis + velocity * self.config.dt + step, turn)
        turned.turn_rate = kin.turn_rate
        return replace(states, kin=turned, held_velocity=velocity,
                       pose=self._kin.pose_body(self.body, self.params, states.walker, turned, self.kin_config))

    def log_likelihood(self, prev: TrackerStates | None, states: TrackerStates, obs: Any) -> np.ndarray:
        penalty = self.config.fallen_log_penalty * states.fallen
        if self.config.likelihood_scale == 0.0:     # dead reckoning: the observations are not looked at
            return -penalty
        pending, self._naming_pending = self._naming_pending, None
        if pending is not None and pending[3] and prev is not None:
            prev = self._mirrored(prev)             # renamed here: the flow compares mirrored with mirrored
        loglik = np.asarray(self.likelihood(prev, states, obs), float)
        if pending is not None:
            self._naming_evidence_of(pending, loglik, states, obs)
        return (self.config.likelihood_scale * loglik - penalty - self.depth_band_penalty(states)
                - self.heading_band_penalty(states))

    def depth_band_penalty(self, states: TrackerStates) -> np.ndarray:
        """(N,) nats taken from walkers whose pelvis strays over the ground beyond the band's half width
        (``depth_band_m``, or ``depth_band_rows`` map rows of the feet row's depth if wider) from the
        frame's one-camera feet-row position (``inference.recovery``, *One camera's depth*); zeros where
        the frame has none (several cameras that triangulate the person, a blob not as tall as the body, the first
        ``depth_band_delay_s`` of the track, recovery off). The feet row
        is an outlier with probability ``depth_band_outlier``: the penalty levels off at about
        -log(outlier) nats, so a feet row far from every walker (hidden feet) changes no weights."""
        r = self.config.recovery
        if self._depth_band is None or r.depth_band_m <= 0:
            return np.zeros(len(states))
        centre, half_width = self._depth_band
        gap = np.linalg.norm(states.pose.markers[:, MARKER_NAMES.index("pelvis"), :2] - centre, axis=1)
        return _band_penalty(gap - half_width, r.depth_band_sigma_m, r.depth_band_outlier)

    def heading_band_penalty(self, states: TrackerStates) -> np.ndarray:
        """(N,) nats taken from walkers heading farther than the band's half width from the direction the frame's
        one-camera feet rows move in (``LostTrackMonitor.heading_band``; a side view shows which way a person walks
        by where they go, hardly by how the body looks): up to 0.5 (excess / ``heading_band_sigma_rad``)^2, levelling
        off at about -log(``depth_band_outlier``); zeros where the frame has no band."""
        r = self.config.recovery
        if self._heading_band is None:
            return np.zeros(len(states))
        direction, half_width = self._heading_band
        off = np.abs(np.angle(np.exp(1j * (states.kin.heading - direction))))
        return _band_penalty(off - half_width, r.heading_band_sigma_rad, r.depth_band_outlier)

    # -- outputs --------------------------------------------------------------------------
    def outputs(self, states: TrackerStates, events: Any | None) -> ParticleOutputs:
        n = len(states)
        contact = np.column_stack([states.kin.contact_point, np.zeros(n)])
        # (held walkers did not make the transition whose events these are)
        struck = (np.zeros(n, bool) if events is None else np.asarray(events.heel_strike, bool)) & (states.reseeded != HELD)
        c = states.control
        pose = states.pose
        if np.any(states.standing > 0.0):      # shown standing (TrackerConfig.held_settle_s), the pelvis kept
            pelvis = pose.markers[:, MARKER_NAMES.index("pelvis"), :2]
            walker, kin = self._kin.standing_body(states.walker, states.kin, pelvis, states.standing, self.body,
                                                  self.params, self.kin_config)
            pose = self._kin.pose_body(self.body, self.params, walker, kin, self.kin_config)
        walker_fields = {k: getattr(states.walker, k) for k in
                         ("stance_angle", "swing_angle", "stance_rate", "swing_rate", "contact_origin")}
        walker_fields.update({k: np.asarray(getattr(c, k), float) for k in
                              ("stiffness", "stiffness_mean_mean", "stiffness_mean_variance", "toe_off_impulse")})
        return ParticleOutputs(
            markers=pose.markers, joint_angles=pose.joint_angles,
            torso_position=pose.markers[:, MARKER_NAMES.index("pelvis")],
            torso_rotation=pose.segments.rotation[:, 0],
            speed=states.speed, stance_leg=states.walker.stance_leg, contact_point=contact,
            heel_strike=struck, strike_point=contact,
            strike_fraction=(np.full(n, np.nan) if events is None
                             else np.where(struck, np.asarray(events.strike_fraction, float), np.nan)),
            walker=walker_fields, reseeded=states.reseeded)


def _band_penalty(excess: np.ndarray, sigma: float, outlier: float) -> np.ndarray:
    """Nats (>= 0) a band takes from values ``excess`` beyond its free half width (<= 0 inside: nothing): a Gaussian
    of ``sigma`` on the excess, mixed with an outlier of probability ``outlier``, so the band's own reading may be
    wrong and the penalty levels off at about -log(outlier)."""
    inlier = -0.5 * (np.maximum(excess, 0.0) / sigma) ** 2
    log_outlier = np.log(outlier)
    return np.logaddexp(0.0, log_outlier) - np.logaddexp(inlier, log_outlier)


# ----------------------------------------------------------------------------- online tracker


@dataclass
class MapTrajectory:
    """MAP state sequence (lineage of the final best particle), one row per tracked frame."""

    frames: np.ndarray          # (F,) frame indices of the input
    stamps_ns: np.ndarray       # (F,)
    markers: np.ndarray         # (F, 13, 3)
    joint_angles: np.ndarray    # (F, J)
    stance_leg: np.ndarray      # (F,)
    heel_strike: np.ndarray     # (F,) bool
    strike_fraction: np.ndarray  # (F,) when in the frame's period the walker struck, 0-1 (NaN where it did not)
    in_view: np.ndarray | None = None   # (F,) bool: the person in view of some camera (inference.visibility)
    marker_names: tuple[str, ...] = MARKER_NAMES
    joint_names: tuple[str, ...] = JOINT_NAMES


#: Marker and joint rows that name the other leg (left <-> right).
_OTHER_SIDE = {name: name.replace("left", "#").replace("right", "left").replace("#", "right") for name in
               MARKER_NAMES + JOINT_NAMES}


def mirror_poses(markers: np.ndarray, joint_angles: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Copies of poses (markers (F, M, 3), joint angles (F, J)) with the frames ``rows`` (bool (F,)) mirrored about
    their own sagittal plane (through the pelvis along the heading, ``torso_yaw``) and left and right swapped: the
    same body with its legs named the other way round (``kinematics.mirrored_legs``)."""
    markers, joint_angles = markers.copy(), joint_angles.copy()
    if not np.any(rows):
        return markers, joint_angles
    pelvis = markers[rows, MARKER_NAMES.index("pelvis"), None, :2]
    heading = joint_angles[rows, JOINT_NAMES.index("torso_yaw")]
    side = np.stack([-np.sin(heading), np.cos(heading)], axis=1)[:, None, :]      # the body's left, (F', 1, 2)
    reflected = markers[rows].copy()
    reflected[..., :2] -= 2.0 * np.sum((reflected[..., :2] - pelvis) * side, axis=-1, keepdims=True) * side
    markers[rows] = reflected[:, [MARKER_NAMES.index(_OTHER_SIDE[n]) for n in MARKER_NAMES]]
    angles = joint_angles[rows][:, [JOINT_NAMES.index(_OTHER_SIDE[n]) for n in JOINT_NAMES]]
    angles[:, JOINT_NAMES.index("torso_roll")] *= -1.0
    joint_angles[rows] = angles
    return markers, joint_angles


def relabel_lineage(markers: np.ndarray, joint_angles: np.ndarray, stance_leg: np.ndarray, flipped: np.ndarray,
                    left_probability: np.ndarray | None = None, renamed_since: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A lineage (markers (F, M, 3), joint angles (F, J), stance legs (F,)) whose particle renamed its legs at the
    frames ``flipped`` (F,) (``TrackerModel._flip_labels``), named one way throughout: every frame before an odd
    number of later flips mirrored (``mirror_poses``), as the flip did to the frames after it, so that no foot
    jumps to the other side at a flip. Which way: as at its last frame, or with ``left_probability`` (F,) (the
    posterior's, per frame) the way the posterior favoured over the lineage's frames (each weighted by how sure
    it was, |p - 0.5|): one particle's last naming is a coin toss where the images hardly tell the legs apart,
    the posterior's frames together are the evidence. ``renamed_since`` (F,) bool: frames named the other way round
    by a later renaming of the whole posterior (the naming test: from the frame since which its evidence favoured
    the other naming up to the renaming; ``flipped`` must not hold the renamings): mirrored too, and the posterior's
    probabilities there read the other way round, as the naming they were measured in was. The frames before
    that onset keep their naming: it was right for them, and the walker went wrong later (a step taken or
    missed), so the feet change sides there."""
    flipped = np.asarray(flipped, int)
    later = np.cumsum(flipped[::-1])[::-1] - flipped                                    # flips after each frame
    odd = later % 2 == 1
    if renamed_since is not None:
        odd = odd ^ np.asarray(renamed_since, bool)
    stance_leg = np.where(odd, 1 - np.asarray(stance_leg), np.asarray(stance_leg))
    if left_probability is not None:
        p = np.asarray(left_probability, float)
        if renamed_since is not None:
            p = np.where(renamed_since, 1.0 - p, p)
        agreement = np.sum(np.abs(p - 0.5) * np.where((stance_leg == LEFT) == (p > 0.5), 1.0, -1.0))
        if agreement < 0:
            odd, stance_leg = ~odd, 1 - stance_leg
    markers, joint_angles = mirror_poses(markers, joint_angles, odd)
    return markers, joint_angles, stance_leg


#: Seconds of the MAP lineage before the live steps' newest frames that name its legs with them (``relabel_lineage``'s
#: vote) and hold the frame before each strike (``Tracker.lineage_steps``).
LINEAGE_STEP_CONTEXT_S = 2.0
#: How often (s) the live steps look at the MAP lineage (its last 3 s named: ~1 ms at 30 Hz, 2 at 60 Hz).
LINEAGE_STEP_EVERY_S = 0.1

#: The fastest the published pelvis moves from one frame to the next (m/s): a walking person's pelvis stays under
#: ~2 m/s, so faster is a jump of the estimate (PublishedPath).
MAX_PUBLISHED_SPEED_M_S = 2.5


class PublishedPath:
    """Where the pose published frame by frame stands: the filtering MAP (the frame's highest-weight particle)
    shifted over the ground so that the live path does not jump when the MAP moves to another particle or a
    particle is re-seeded. Each frame the published pelvis moves as the MAP particle's own walk moved over the
    frame (from its parent a frame ago, less any re-seeding jump); the offset that leaves between the published
    and the MAP pelvis shrinks by ``settle_m_s`` x dt, so the published path catches up with the MAP within
    |offset| / ``settle_m_s`` s, and its step is never faster than ``MAX_PUBLISHED_SPEED_M_S`` (the offset keeps
    the rest)."""

    def __init__(self, dt: float, settle_m_s: float = JUMP_SPREAD_M_S) -> None:
        self.dt = float(dt)
        self.settle_m_s = float(settle_m_s)
        self._pelvis: np.ndarray | None = None       # (N, 2) the last frame's particles' pelvis
        self._published: np.ndarray | None = None    # (2,) the last published pelvis
        self.offset = np.zeros(2)                    # MAP pelvis minus published pelvis (m)

    def update(self, pelvis_xy: np.ndarray, ancestors: np.ndarray, jump: np.ndarray, best: int) -> np.ndarray:
        """The offset (2,) m to take from the MAP pose of this frame: ``pelvis_xy`` (N, 2) of the frame's particles,
        their ``ancestors`` among the last frame's, re-seeding ``jump`` (N, 3), the MAP particle ``best``."""
        pelvis = np.array(pelvis_xy, float)
        if self._pelvis is not None:
            walked_from = self._pelvis[int(ancestors[best])] + jump[best, :2]
            offset = walked_from - self._published
            size = float(np.linalg.norm(offset))
            offset = offset * max(0.0, 1.0 - self.settle_m_s * self.dt / size) if size > 0 else offset
            step = pelvis[best] - offset - self._published
            fastest = MAX_PUBLISHED_SPEED_M_S * self.dt
            if np.linalg.norm(step) > fastest:
                offset = pelvis[best] - (self._published + step * fastest / np.linalg.norm(step))
            self.offset = offset
        self._pelvis = pelvis
        self._published = self._pelvis[best] - self.offset
        return self.offset.copy()


class Tracker:
    """Online tracker: push one observation per frame, get posterior summaries (lag tau frames). Once the person
    has been out of every camera's view for ``ViewConfig.end_after_s`` the track ends (``ended``; module
    ``inference.visibility``): that frame's summary is the last, and later pushes complete nothing."""

    def __init__(self, model: TrackerModel, config: TrackerConfig | None = None, track_id: int = 1) -> None:
        self.model = model
        self.track_id = int(track_id)
        self.config = config or model.config
        self.filter = ParticleFilter(model, self.config.smc)
        self.history = AncestryHistory()
        self._frames: list[tuple[int, int]] = []   # (frame index, stamp) in push order
        self._last_step: FilterStep | None = None
        self.published = PublishedPath(self.config.dt)
        self._left_probability: list[float] = []    # the posterior's stance-left probability per completed frame
        self._in_view: list[bool] = []              # the person in view of some camera, per completed frame
        self._features: dict[int, tuple] = {}       # push index -> the frame's image features, until completed
        self.views = ViewMonitor(self.config.dt, self.config.view)
        self.ended: TrackEnd | None = None
        self.live_steps = LineageSteps()

    def push(self, frame_index: int, stamp_ns: int, obs: Any) -> list[PosteriorSummary]:
        """Add the observation of one frame; returns the summaries completed (in frame order)."""
        if self._frames and stamp_ns <= self._frames[-1][1]:
            raise ValueError(f"frame stamps must increase: {stamp_ns} after {self._frames[-1][1]}")
        # the filter's step from the stamps: a gap of k frame periods (frames no camera delivered) is k frames of the
        # walker's motion, so the track does not slip in time; jitter within half a period is not a gap
        self.model.frames_per_step = (max(1, round((stamp_ns - self._frames[-1][1]) * 1e-9 / self.config.dt))
                                      if self._frames else 1)
        if self.ended is not None:
            return []
        if isinstance(obs, ImageObservation):
            self._features[len(self._frames)] = tuple(obs.features)
        self._frames.append((int(frame_index), int(stamp_ns)))
        return self._completed(self.filter.push(obs))

    def finish(self) -> list[PosteriorSummary]:
        """Flush the frames still waiting for look-ahead observations."""
        return [] if self.ended is not None else self._completed(self.filter.finish(), finishing=True)

    def released(self) -> "Tracker":
        """This ended track without its particles and pending frames (what ``map_trajectory`` needs stays); returns
        self."""
        self.filter = None
        self._features.clear()
        return self

    @property
    def renamed_frames(self) -> list[int]:
        """Input frame indices at which the whole posterior renamed the legs (``TrackerConfig.naming_test_particles``)."""
        return [self._frames[f][0] for f in self.model.renamed_frames if f < len(self._frames)]

    @property
    def completed_frames(self) -> int:
        """Frames whose summaries are out."""
        return len(self._in_view)

    def _completed(self, steps: list[FilterStep], finishing: bool = False) -> list[PosteriorSummary]:
        """The summaries of ``steps``, up to the one that ends the track (``finishing``: the last one does)."""
        out = []
        for k, step in enumerate(steps):
            out.append(self._summarize(step, last=finishing and k == len(steps) - 1))
            if self.ended is not None:
                break
        return out

    def _summarize(self, step: FilterStep, last: bool = False) -> PosteriorSummary:
        frame_index, stamp_ns = self._frames[step.frame]
        features = self._features.pop(step.frame, None)
        out = self.model.outputs(step.states, step.info)
        payload = {"markers": out.markers.astype(np.float32), "joint_angles": out.joint_angles.astype(np.float32),
                   "stance_leg": out.stance_leg.copy(), "heel_strike": out.heel_strike.copy(),
                   "strike_fraction": out.strike_fraction.astype(np.float32), "jump": step.states.jump.astype(np.float32),
                   "flipped": step.states.flipped.copy()}
        self.history.append(None if step.frame == 0 else step.ancestors, payload)
        self._last_step = step
        summary = summarize(frame_index, stamp_ns, step.log_weights, out, MARKER_NAMES, JOINT_NAMES,
                            step.resampled, cloud_size=self.config.cloud_size)
        self._left_probability.append(summary.stance_left_probability)
        views = (camera_views(self.model.cameras, features, summary.mean_markers, self.config.view)
                 if features is not None and self.model.cameras else ())
        in_view = not views or any(v.in_view for v in views)
        self._in_view.append(in_view)
        self.ended = self.views.update(frame_index, stamp_ns, views)
        summary = replace(summary, track_id=self.track_id, person_in_view=in_view,
                          cameras_in_view=tuple(v.camera for v in views if v.in_view),
                          legs_renamed=bool(self.model.naming_decisions.get(step.frame, False)),
                          steps=self.lineage_steps(final=last or self.ended is not None))
        offset = self.published.update(out.markers[:, MARKER_NAMES.index("pelvis"), :2], step.ancestors,
                                       step.states.jump, step.best_index)
        if not offset.any():
            return summary
        shift = np.append(offset, 0.0)
        return replace(summary, map_markers=summary.map_markers - shift,
                       map_torso_position=summary.map_torso_position - shift)

    def map_trajectory(self, first: int = 0) -> MapTrajectory:
        """Lineage of the highest-weight particle of the last completed frame (from push index ``first`` on), its legs
        named the way the posterior favoured (``relabel_lineage``; one way throughout but where the whole posterior
        renamed them), re-seedings' jumps spread over the frames before them (``smooth_jumps``)."""
        if self._last_step is None:
            raise ValueError("no frame has been completed yet")
        traj = self.history.trajectory(self._last_step.best_index, first)
        count = len(self.history)
        frames = np.array([f for f, _ in self._frames[first:count]], np.int64)
        stamps = np.array([s for _, s in self._frames[first:count]], np.int64)
        renamed = np.zeros(count, bool)           # the frames each renaming of the whole posterior names anew
        for frame, onset in self.model.naming_onsets.items():
            renamed[onset:min(frame, count)] ^= True
        own_flips = traj["flipped"] & ~np.isin(np.arange(first, count), self.model.renamed_frames)
        markers, angles, stance = relabel_lineage(traj["markers"].astype(float), traj["joint_angles"].astype(float),
                                                  traj["stance_leg"], own_flips, self._left_probability[first:count],
                                                  renamed[first:])
        markers, angles = smooth_jumps(markers, angles, traj["jump"].astype(float), self.model.config.dt)
        return MapTrajectory(frames, stamps, markers, angles, stance, traj["heel_strike"].astype(bool),
                             traj["strike_fraction"].astype(float), np.array(self._in_view[first:count], bool))

    def lineage_steps(self, final: bool = False) -> tuple[Step, ...]:
        """The steps the MAP lineage has carried for ``TrackerConfig.step_lag_s`` since the last call, looked for every
        ``LINEAGE_STEP_EVERY_S`` (``final``: every step up to the last completed frame, at the track's end), from its
        last ``LINEAGE_STEP_CONTEXT_S`` + lag (``gait_events.LineageSteps``), timed in s of the stamps' clock."""
        count = len(self.history)
        until = count - 1 - (0 if final else round(self.config.step_lag_s / self.config.dt))
        if until - self.live_steps.taken_until < (1 if final else max(1, round(LINEAGE_STEP_EVERY_S / self.config.dt))):
            return ()
        first = max(0, self.live_steps.taken_until - round(LINEAGE_STEP_CONTEXT_S / self.config.dt))
        lineage = self.map_trajectory(first)
        heels = lineage.markers[:, [MARKER_NAMES.index("left_heel"), MARKER_NAMES.index("right_heel")], :2]
        return tuple(self.live_steps.add(first, until, lineage.frames, lineage.stamps_ns, heels, lineage.stance_leg,
                                         lineage.strike_fraction, lineage.in_view))


def marker_likelihood(sigma_m: float = 0.03, names: tuple[str, ...] = MARKER_NAMES) -> LikelihoodFn:
    """Likelihood of observed 3D markers (obs: (13, 3) array, NaN = unobserved), isotropic Gaussian.

    For tests and benchmarks of the dynamics/kinematics part of the tracker without images.
    """
    rows = [MARKER_NAMES.index(n) for n in names]

    def loglik(prev: TrackerStates | None, states: TrackerStates, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, float)[rows]
        seen = np.all(np.isfinite(obs), axis=1)
        d = states.pose.markers[:, rows][:, seen] - obs[seen]
        return -0.5 * np.sum(d * d, axis=(1, 2)) / sigma_m**2

    return loglik


@dataclass(frozen=True)
class ImageObservation:
    """Image features of one frame from every camera (camera order of the likelihood's cameras)."""

    features: tuple[Any, ...]     # vision.features.FrameFeatures per camera (occlusion masks applied)


def image_likelihood(body: BodyDescription, cameras: list[Any],
                     config: LikelihoodConfig | None = None) -> LikelihoodFn:
    """The image likelihood of paper Sec. 5.1 (eq. 9-12) over ``cameras`` (vision.likelihood; ``config``:
    its settings, default ``LikelihoodConfig()``), divided by the number of cameras: with the tempering
    (``TrackerConfig.likelihood_scale``) this keeps the weight of the evidence the same for any number of
    cameras. Summed as in eq. (12), two cameras at scale 0.1 lost the
    walker in 1 of 6 tracker seeds (205 mm); averaged, 17-51 mm (mean 30) over the same seeds."""
    from awalker_tracker.vision.likelihood import LikelihoodConfig, SilhouetteMemo, log_likelihood

    parts = body.parts
    config = LikelihoodConfig() if config is None else config
    memo = SilhouetteMemo()   # each frame's poses are the next frame's previous poses

    def loglik(prev: TrackerStates | None, states: TrackerStates, obs: ImageObservation) -> np.ndarray:
        prev_segments = states.pose.segments if prev is None else prev.pose.segments
        return log_likelihood(parts, states.pose.segments, prev_segments, cameras, list(obs.features),
                              config=config, memo=memo) / len(cameras)

    return loglik
