"""Batch Monte Carlo experiments reproducing the paper's simulations (section 4).

`mexgen-gcs experiment follow|localise --model ... --methods pim,mc8,mexgen --starts N
--reps N --out DIR` (see :mod:`.cli`). The world (truth tags, a point-mass vehicle, the radio)
is simulated in process on simulated time; the decisions come from the flight path's own
MissionCore, planner and guidance. Modules: scenario (settings, the mission each run flies),
seeds (paired seeds), world, runner (one run), parallel (process pool or Dask), store (the
output directory), report (summary.md and plots), progress, cli.

Frames: local ENU metres about the area centre throughout.
"""
