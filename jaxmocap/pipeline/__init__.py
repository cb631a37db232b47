"""The main job: a video in, whole-body SMPL-X motion out (``jaxmocap run`` and ``jaxmocap demo``)."""

from jaxmocap.pipeline.job import RunReport, run

__all__ = ["RunReport", "run"]
