"""Tracking profiles: the one set of run defaults that `awalker track` (its options, ``pipeline.TrackOptions``)
and the tracker node (its parameters) read, under a name.

A profile names the particle count and takes every other setting from the core's configs (``SMCConfig``,
``TrackerConfig``, ``RecoveryConfig``), so there is one place for each default:

- ``accurate`` (the default of both): 15000 particles. The paper used 5000; on the real walks 15000 reach
  poses the image likelihood ranks higher (docs/tracking.md, "The filter": two cameras 56 mm
  against 59, one camera 73 against 74, the worst runs 104 and 185 mm against 142 and 277) at about 3 times
  the time per frame.
- ``realtime``: 5000 particles, for a live camera (the paper's number, and the tracker node's before the
  profiles): about 3 times less time per frame (docs/results.md, "Speed", for the frames/s of each).
"""
from __future__ import annotations

from dataclasses import dataclass

from awalker_tracker.errors import InputError
from awalker_tracker.inference.filter_model import TrackerConfig
from awalker_tracker.inference.recovery import RecoveryConfig
from awalker_tracker.inference.smc import SMCConfig


@dataclass(frozen=True)
class TrackingProfile:
    """Defaults of a tracking run: particles N (at most, with the adaptive count's fewest), look-ahead tau
    (frames), trust gamma, resampling, seed, the image likelihood's exponent, the particles' leg-length spread
    (log), recovery switches and one camera's depth band (m)."""

    num_particles: int
    min_particles: int = SMCConfig.min_particles     # the adaptive count's fewest (SMCConfig; 0: N throughout)
    lookahead: int = SMCConfig.lookahead
    trust: float = SMCConfig.trust
    resample_fraction: float = SMCConfig.resample_fraction
    resampling: str = SMCConfig.resampling
    seed: int = 0
    likelihood_scale: float = TrackerConfig.likelihood_scale
    leg_scale_spread: float = TrackerConfig.leg_scale_spread
    reseed_fallen: bool = RecoveryConfig.reseed_fallen
    reacquire: bool = RecoveryConfig.reacquire
    hold_still: bool = RecoveryConfig.hold_still
    depth_band_m: float = RecoveryConfig.depth_band_m

    def fewest_for(self, particles: int) -> int:
        """The profile's fewest particles for a run of ``particles`` (N): never more than N, so an N given below
        the profile's fewest tracks N throughout."""
        return min(int(self.min_particles), int(particles))

    @property
    def recovery(self) -> bool:
        """Every recovery switch on (`awalker track` has one switch for the three: --no-recovery)."""
        return self.reseed_fallen and self.reacquire and self.hold_still


PROFILES: dict[str, TrackingProfile] = {
    "accurate": TrackingProfile(num_particles=15000),
    "realtime": TrackingProfile(num_particles=5000),
}
DEFAULT_PROFILE = "accurate"


def particle_count_text(particles: int, fewest: int) -> str:
    """How a run's particle count reads in its log: "15000 particles", or with the adaptive count (``fewest`` > 0)
    "5000-15000 particles (adaptive)"."""
    if 0 < fewest < particles:
        return f"{fewest}-{particles} particles (adaptive)"
    return f"{particles} particles"


def tracking_profile(name: str, where: str = "profile") -> TrackingProfile:
    """The profile called ``name``; an InputError naming ``where`` (the option or parameter) if there is none."""
    if name not in PROFILES:
        raise InputError(f"{where}: unknown profile {name!r}; expected one of {', '.join(PROFILES)}")
    return PROFILES[name]
