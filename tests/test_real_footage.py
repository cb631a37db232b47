"""Real footage with a 3D reference: Pose2Sim's oblique view from above and behind (`cam03`, 100 frames), run as a
user runs it and scored as `bench/accuracy.py` scores it (docs/BENCHMARKS.md, "Accuracy on real footage"), beside
BlazePose's own monocular 3D."""

import pytest

import smplx_jax
from bench import accuracy
from bench.live import agreement_mm
from conftest import assert_one_body
from jaxmocap.live import LiveConfig, live
from jaxmocap.motion import read_motion


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("cam03")


@pytest.fixture(scope="module")
def scored(run_dir):
    stages = accuracy.run_stages(accuracy.VIEWS["cam03"], run_dir)
    return accuracy.report_view("cam03", stages, accuracy.load_reference())


def test_one_person_is_one_identity(scored, run_dir):
    assert [p.name for p in (run_dir / "people").iterdir()] == ["0"]


def test_one_body_over_the_whole_clip(scored, run_dir):
    assert_one_body(read_motion(run_dir / "motion.npz"))


def test_the_fit_sits_on_the_person(scored):
    motion = scored["motion"]
    assert motion["valid_share"] >= 0.95
    assert motion["reprojection_median_px"] <= 12.0, motion["reprojection_median_px"]
    assert motion["reprojection_over_40px"] <= 0.05


def test_rotations_are_coherent_over_time(scored):
    """No twist flips between frames 1/60 s apart in the motion (the clip fit); before it, the frames' IK start
    (each frame from its own BlazePose heavy landmarks) turns a few joints."""
    for stage, flips in (("ik", 0.02), ("motion", 0.003)):
        assert scored[stage]["rotation_change_median_deg"] <= 5.0, (stage, scored[stage])
        assert scored[stage]["rotation_change_over_45deg"] <= flips, (stage, scored[stage])


def test_3d_against_the_blazepose_landmarks_it_starts_from(scored):
    blazepose, motion = scored["blazepose"], scored["motion"]
    assert motion["frames_scored"] >= 80
    assert motion["accel_error_mm"] <= blazepose["accel_error_mm"], (motion, blazepose)
    assert motion["flexion_mae_deg"] <= blazepose["flexion_mae_deg"], (motion, blazepose)
    assert motion["pa_mpjpe_mm"] <= 0.8 * blazepose["pa_mpjpe_mm"], (motion, blazepose)


def test_live_stays_with_the_offline_run_over_the_whole_clip(scored, run_dir, tmp_path):
    """The clip solved live, frame by frame, against the offline run (one fit of the whole clip), both on BlazePose
    heavy: measured 38.7 mm PA-MPJPE over the body joints (28.0 mm when the offline run too fitted frames alone; the
    whole clip's fit holds the 3D landmarks' bone directions and the motion's accelerations, which the live path's
    fit of each frame does not yet)."""
    live(LiveConfig(accuracy.VIEWS["cam03"], record=tmp_path, progress=False, landmarks="heavy"))  # the run's
    model = smplx_jax.load_model(smplx_jax.default_model_path())
    error, frames = agreement_mm(model, read_motion(tmp_path / "motion.npz"), read_motion(run_dir / "motion.npz"))
    assert frames >= 95 and error <= 42.0, (error, frames)
