"""Leg length and stance leg from the images: the filter's evidence over a few candidates (issue 12 §1, §3).

A tape measure's leg length is easily a few per cent off, and a body scaled to the seen height takes
its leg length from average proportions. The leg length sets how high the walker carries the pelvis
(the walker's L, ``BodyDescription.leg_length``), so a leg too long puts pelvis, hips and thorax too
high however well the rest is tracked (real walks: the tape's leg 4.5 cm longer than the person's hip
height, the pelvis 75 mm high; docs/tracking.md, "Body fit").

``fit_leg_length`` runs the tracker's own filter once per candidate, each with thigh and shank scaled
by a factor (``BodyDescription.legs_scaled``; ankle, feet, torso and head unchanged), over the first
``frames`` frames, and keeps the candidate with the highest evidence
log p(z_1:T) = sum_t log sum_j w_{t-1,j} p(z_t | s_t^j) (``FilterStep.log_evidence``). The image likelihood
for this comparison counts the person's foreground above the head against the body
(``LikelihoodConfig.head_top_weight`` 1): without it the evidence preferred legs 3 % short on our own renders,
where the drawn body is the tracker's.

Measured (``awalker fitbody`` on the real-walks benchmark's hand-started runs, tracker seeds
0-2, then ``awalker track --body`` the fitted body; docs/tracking.md, "Body fit"): two cameras,
median of the walk medians 83 mm against 91 with the tape's body (better on 7 of 12 walks, worse on 4),
relative 51 against 56; one camera 130 against 118 (better on 6, worse on 5: depth, seed noise), relative
53 against 58. Hands off (the body scaled to the seen height, candidates 0.97-1.12): one camera 147 against
191 (relative 60 against 72), two cameras 84 against 84 (relative 53 against 60). Our own renders: the
drawn length kept in 11 of 12 runs.

With ``BodyFitConfig.keep_height`` each candidate keeps the body's standing height, its torso and head giving
what the legs gain: for a body scaled to a height the images measured (``awalker_tools.fit_body`` sets it with
two or more cameras). Measured (hands off, two cameras, 15000 particles, seeds 0-4): 63.1 mm median
of the walk medians against 68.0 with the legs added to the seen height, per run -3.3 mm (36 of 60 better).

``fit_stance_leg`` compares, the same way, the two stance legs a start that does not name one leaves open
(the automatic start; a start description with ``stance_leg: unknown``): one filter per leg, each drawing
its phase as a start naming that leg does, and keeps the leg with the higher evidence. One camera sees a
walk from the side and, with both legs dressed alike, tells them apart only by small differences summed
over many frames; a single filter over both legs settles on one in its first frames and keeps it. The
evidence is a Monte Carlo estimate whose spread from seed to seed is of the size of the difference it
weighs (one camera, 5000 particles, 60 frames: +-20 nats), so each leg's evidence is averaged over
``stance_repeats`` filters of their own seeds (log of the mean of exp), and while the two legs lie within
``stance_tie_nats`` of each other, over as many again, up to ``stance_max_repeats`` per leg: more filters
only where the first ones left it open.
Measured on the real-walks benchmark, one camera, hands off, 15000 particles, tracker seeds 0-4 (docs/tracking.md,
"Body fit"): the legs named the other way round in 6 of 60 runs against 15 when
the filter chose, 89.4 mm median of the walk medians against 100.2; two cameras 0 of 60 against 1, 68.0 mm
against 66.6 (per run a median -3.0 mm, within seed noise).
Weighing near ties again (within 10 nats, up to 6 filters per leg; docs/tracking.md, "Body fit"): 4 of 60
runs swapped against 6, 87.8 mm against 89.4; 29 of the 60 one-camera runs took the extra filters.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, replace

import numpy as np
from scipy.special import logsumexp

from awalker_tracker.blocks import thread_count
from awalker_tracker.inference.filter_model import StartDescription, TrackerConfig, TrackerModel
from awalker_tracker.inference.smc import ParticleFilter
from awalker_tracker.model.body import BodyDescription
from awalker_tracker.model.walker import LEFT, LEG_NAMES, RIGHT


@dataclass(frozen=True)
class BodyFitConfig:
    """Candidates and effort of the leg-length fit."""

    leg_factors: tuple[float, ...] = (0.91, 0.94, 0.97, 1.0, 1.03)   # thigh and shank x factor
    # True: each candidate keeps the body's standing height, its torso and head scaled by what the legs gain
    # or lose (``BodyDescription.legs_scaled(keep_height=True)``): for a height the images measured (module
    # docstring)
    keep_height: bool = False
    frames: int = 60                 # frames of evidence from the start frame (2 s at 30 Hz)
    particles: int = 5000            # per candidate (2500 picked less reliably: README)
    seed: int = 0
    stance_repeats: int = 2          # filters (seeds seed, seed + 1, ...) per stance leg and round (module docstring)
    stance_tie_nats: float = 10.0    # legs closer than this (log evidence) are weighed again with more filters
    stance_max_repeats: int = 6      # filters per stance leg at most

    def __post_init__(self) -> None:
        if not self.leg_factors or min(self.leg_factors) <= 0.5 or max(self.leg_factors) >= 1.5:
            raise ValueError(f"BodyFitConfig: leg factors must lie in (0.5, 1.5): {self.leg_factors}")
        if self.frames < 2 or self.particles < 10 or self.stance_repeats < 1:
            raise ValueError(f"BodyFitConfig: frames >= 2, particles >= 10 and stance_repeats >= 1 needed: {self}")
        if self.stance_max_repeats < self.stance_repeats or self.stance_tie_nats < 0:
            raise ValueError(f"BodyFitConfig: stance_max_repeats >= stance_repeats and stance_tie_nats >= 0 "
                             f"needed: {self}")


@dataclass(frozen=True)
class BodyFit:
    """The candidate kept (``factor``, its ``body``) and every candidate's log evidence (nats)."""

    factor: float
    body: BodyDescription
    log_evidence: dict[float, float]
    frames: int


@dataclass(frozen=True)
class StanceFit:
    """The stance leg kept (``leg``: LEFT or RIGHT at the start frame) and each leg's log evidence (nats)."""

    leg: int
    log_evidence: dict[int, float]
    frames: int
    filters: int          # filters per leg that weighed it


def _used_observations(observations: Sequence[object], config: BodyFitConfig) -> list[object]:
    if not observations:
        raise ValueError("body fit: no observations from the start frame on")
    return list(observations[: config.frames])


def _log_evidence(candidates: dict[object, tuple[BodyDescription, StartDescription, int]],
                  likelihood_for: Callable[[BodyDescription], object], used: list[object],
                  tracker_config: TrackerConfig, config: BodyFitConfig, cameras: Sequence[object] | None,
                  progress: Callable[[object, float, int], None] | None,
                  check: Callable[[], None] | None = None) -> dict[object, float]:
    """log p(z_1:T) (nats) of each candidate (key -> its body, start and filter seed), in the candidates'
    order; ``check`` is called before each frame of each candidate and may raise to stop the fit (a signal). The candidates are independent filters with their own random streams: they run on as many threads
    as there are cores (the kernels release the GIL; one candidate's numpy and Python overlap another's
    kernels), each the same bit for bit as alone. Measured (6 candidates x 60 frames x 5000
    particles, a real walk's first pass): two cameras 19.0 -> 13.6 s, one camera 14.7 -> 12.7 s."""

    def evidence(key: object) -> tuple[float, int]:
        body, start, seed = candidates[key]
        # (a fixed count: the candidates' evidences are compared with each other)
        smc = replace(tracker_config.smc, num_particles=config.particles, seed=seed, min_particles=0)
        # (no naming test: the stance-leg candidates are the two namings, each kept by its own filter)
        run_config = replace(tracker_config, smc=smc, naming_test_particles=0)
        model = TrackerModel(body, start, likelihood_for(body), run_config,
                             cameras=list(cameras) if cameras is not None else None)
        pf = ParticleFilter(model, smc)
        log_evidence = []
        for obs in used:
            if check is not None:
                check()
            log_evidence += [step.log_evidence for step in pf.push(obs)]   # (the steps are not kept)
        log_evidence += [step.log_evidence for step in pf.finish()]
        return float(np.sum(log_evidence)), len(log_evidence)

    result: dict[object, float] = {}
    with ThreadPoolExecutor(max_workers=max(1, min(thread_count(), len(candidates))),
                            thread_name_prefix="awalker-bodyfit") as pool:
        futures = {pool.submit(evidence, key): key for key in candidates}
        for future in as_completed(futures):
            key = futures[future]
            result[key], count = future.result()
            if progress is not None:
                progress(key, result[key], count)
    return {key: result[key] for key in candidates}


def _best(evidence: dict[object, float], lost: str) -> object:
    """The candidate with the highest finite evidence; ValueError(``lost``) when none is finite."""
    finite = {key: e for key, e in evidence.items() if np.isfinite(e)}
    if not finite:
        raise ValueError(lost)
    return max(finite, key=finite.get)


def fit_leg_length(body: BodyDescription, start: StartDescription, likelihood_for: Callable[[BodyDescription], object],
                   observations: Sequence[object], tracker_config: TrackerConfig,
                   config: BodyFitConfig = BodyFitConfig(), cameras: Sequence[object] | None = None,
                   progress: Callable[[str], None] | None = None, check: Callable[[], None] | None = None) -> BodyFit:
    """Fit the leg length of ``body`` (module docstring). ``observations``: one per frame from the start
    frame on (the first ``config.frames`` are used); ``likelihood_for(body)``: the likelihood function for
    a candidate body; ``tracker_config``: the run's (its particle count and seed are replaced by the fit's);
    ``check``: called before each frame of each candidate filter, it may raise to stop the fit."""
    used = _used_observations(observations, config)

    def report(factor: object, evidence: float, count: int) -> None:
        if progress is not None:
            progress(f"legs x{factor:.2f} (leg length {body.legs_scaled(factor).leg_length:.3f} m"
                     + (", height kept" if config.keep_height else "") + f"): log evidence {evidence:.1f} over "
                     f"{count} frames")

    evidence = _log_evidence({factor: (body.legs_scaled(factor, config.keep_height), start, config.seed)
                              for factor in config.leg_factors},
                             likelihood_for, used, tracker_config, config, cameras, report, check)
    best = _best(evidence, "fit_leg_length: every candidate lost the person (evidence -inf)")
    return BodyFit(best, body.legs_scaled(best, config.keep_height), evidence, len(used))


def fit_stance_leg(body: BodyDescription, start: StartDescription, likelihood_for: Callable[[BodyDescription], object],
                   observations: Sequence[object], tracker_config: TrackerConfig,
                   config: BodyFitConfig = BodyFitConfig(), cameras: Sequence[object] | None = None,
                   progress: Callable[[str], None] | None = None, check: Callable[[], None] | None = None) -> StanceFit:
    """The stance leg at ``start``'s frame with the higher evidence (module docstring), each leg's evidence
    the log of the mean of exp over its filters (seeds ``config.seed`` on): ``config.stance_repeats`` per leg,
    and as many again while the two legs lie within ``config.stance_tie_nats`` of each other, up to
    ``config.stance_max_repeats``. Arguments as for ``fit_leg_length``; ``start.stance_leg`` is replaced by
    each leg in turn."""
    used = _used_observations(observations, config)

    def report(key: object, evidence: float, count: int) -> None:
        if progress is not None:
            leg, repeat = key
            progress(f"stance leg {LEG_NAMES[leg]} (filter {repeat + 1}): log evidence {evidence:.1f} over "
                     f"{count} frames")

    evidence: dict[tuple[int, int], float] = {}
    filters, more = 0, config.stance_repeats
    while more > 0:
        candidates = {(leg, repeat): (body, replace(start, stance_leg=leg), config.seed + repeat)
                      for leg in (LEFT, RIGHT) for repeat in range(filters, filters + more)}
        evidence.update(_log_evidence(candidates, likelihood_for, used, tracker_config, config, cameras, report, check))
        filters += more
        per_leg = {leg: float(logsumexp([evidence[(leg, r)] for r in range(filters)]) - np.log(filters))
                   for leg in (LEFT, RIGHT)}
        margin = abs(per_leg[LEFT] - per_leg[RIGHT])
        # another round while the legs lie within the tie (NaN: both lost, no more) and filters remain
        more = min(config.stance_repeats, config.stance_max_repeats - filters) if margin < config.stance_tie_nats else 0
        if more and progress is not None:
            progress(f"the legs lie {margin:.1f} nats apart (< {config.stance_tie_nats:g}): {more} more filters per leg")
    return StanceFit(_best(per_leg, "fit_stance_leg: both stance legs lost the person (evidence -inf)"), per_leg,
                     len(used), filters)
