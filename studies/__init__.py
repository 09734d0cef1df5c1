"""Studies: many runs of the simulated testbed compared across methods, seeds and settings.

- ``sweep``: ``mapupdate sweep``, the cross product of a spec, run on a process pool (or as
  Ray tasks through ``sweep_ray``) and resumed when killed;
- ``study_report``: the results table, the summary with confidence intervals and the figures.
"""
