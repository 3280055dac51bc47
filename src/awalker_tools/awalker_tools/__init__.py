"""awalker tools: bag conversion, replay, synthesis, tracking runs, evaluation, the CLI."""

#: Particles of an `awalker track` run (``pipeline.TrackOptions``, the track and demo commands) unless
#: --particles says otherwise. The paper used 5000; on the real walks 15000 reach poses the image likelihood
#: ranks higher (README "Not the body, not the likelihood": two cameras 56 mm against 59, one camera 73 against
#: 74, the worst runs 104 and 185 mm against 142 and 277) at about 3 times the time per frame. Live, the tracker
#: node's num_particles keeps 5000 for real time.
TRACK_PARTICLES = 15000
