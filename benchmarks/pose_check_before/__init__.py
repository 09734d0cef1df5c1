"""The pose check as it was before its fused kernels: a frozen copy of
``localization/confidence.py`` and the kernels it called, kept only so that
``benchmarks/bench_pose_check.py`` can time the two side by side and the tests can check that
both give the same verdicts and refined poses. Configuration, beam selection and the map's
distance field are the live package's. Not used by anything else; not maintained."""

from .confidence import PoseCheck, PoseCheckConfig

__all__ = ["PoseCheck", "PoseCheckConfig"]
