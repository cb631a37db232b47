"""The main job: a video in, whole-body SMPL-X motion out (``jaxmocap run`` and ``jaxmocap demo``)."""

from jaxmocap.pipeline.job import RunReport, fitted_bodies, initial_bodies, run
from jaxmocap.pipeline.observe import Observations, observe

__all__ = ["Observations", "RunReport", "fitted_bodies", "initial_bodies", "observe", "run"]
