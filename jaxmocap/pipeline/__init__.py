"""The main job: a video in, whole-body SMPL-X motion out (``jaxmocap run``, ``demo`` and ``batch``).

    from jaxmocap.pipeline import RunConfig, run
    report = run(RunConfig("video.mp4", exports=("bvh",)), "out")

Modules: `config` (`RunConfig`), `entry` (`run`, every mode's entry), `job` (`run_bodies`, ``--mode whole`` and
``body``, which reads as its stages), `hands_job` (`run_hands`, ``--mode hands``: hands alone, ``hands.npz``), `stages`
(observations -> initial bodies -> the clip fit -> motion arrays), `whole_clip` (each person's whole clip as one fit, in
windows by frame number), `regress` (FrankMocap's regressors in place of IK and the clip fit), `tracks` (what the stages
hand each other), `merge_tracks` (one person's tracks joined), `report` (`RunReport`), `chunks` (frames in chunks and
the resumable chunk store), `outputs` (OpenPose JSON, overlay, exports, FrankMocap pickles), `observe` (the detector's
person as arrays, repaired), `fit_folder` (``jaxmocap fit``), `stage_clock` (stage timing), `exemplar` and `hand_boxes`
(parts of the regressors' path). Imports run one way: `entry` -> the jobs -> the rest.
"""

from jaxmocap.pipeline.config import RunConfig
from jaxmocap.pipeline.entry import run
from jaxmocap.pipeline.observe import Observations, observe
from jaxmocap.pipeline.report import RunReport
from jaxmocap.pipeline.stages import initial_bodies, motion_arrays, observations
from jaxmocap.pipeline.tracks import Bodies, Chunk
from jaxmocap.pipeline.whole_clip import fitted_clip, fitted_track

__all__ = ["Bodies", "Chunk", "Observations", "RunConfig", "RunReport", "fitted_clip", "fitted_track", "initial_bodies",
           "motion_arrays", "observations", "observe", "run"]
