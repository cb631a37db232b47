"""Exemplar fine-tuning (``integrate.eft``): a small random body regressor fitted to known 2D keypoints, and
``jaxmocap run --integration eft`` on frames of the sample clip."""

import inspect
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import nnx

import smplx_jax
from jaxmocap.cli import main
from jaxmocap.integrate import EFTConfig, fine_tune
from jaxmocap.integrate.eft import _keypoints
from jaxmocap.motion import read_motion
from jaxmocap.regressors import BodyConfig, BodyRegressor, initialised
from smplx_jax.rotations import rotvec_to_rotmat

CLIP = Path(__file__).parents[1] / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"
FRAMES, SIZE = 4, 32  # every call below has these shapes, so each configuration compiles once
CONFIG = EFTConfig(trainable="layer4")  # per-frame convolutions (and frozen BatchNorm) at a small cost


@pytest.fixture(scope="module")
def problem():
    """ResNet-18 regressor with random weights whose output starts near the mean body (as a trained one does);
    targets: its own predictions with bent shoulders, elbows and a knee, projected to crop pixels. The last
    frame has no keypoints at all, the third no legs."""
    network = initialised(lambda: BodyRegressor(BodyConfig(depth=18), rngs=nnx.Rngs(0)))
    upright = jnp.array([1.0, 0, 0, -1, 0, 0])  # pi about x: y down
    network.init_pose[...] = jnp.concatenate([upright, jnp.tile(jnp.array([1.0, 0, 0, 1, 0, 0]), 23)])
    network.init_cam[...] = jnp.array([0.9, 0.0, 0.0])
    for head in (network.decpose, network.decshape, network.deccam):
        head.kernel[...] = 0.01 * head.kernel[...]
    model = smplx_jax.load_model(smplx_jax.default_model_path())
    crops = jax.random.normal(jax.random.key(1), (FRAMES, SIZE, SIZE, 3))
    start = network(crops)
    bend = np.zeros((FRAMES, 24, 3), np.float32)
    bend[:, 16, 2], bend[:, 17, 2], bend[:, 18, 1], bend[:, 4, 0] = -0.8, 0.8, -0.8, 0.6
    bend += np.random.default_rng(0).normal(0, 0.1, bend.shape).astype(np.float32)
    rotmats = start.rotmats @ rotvec_to_rotmat(jnp.asarray(bend))
    xy = jax.vmap(_keypoints, in_axes=(None, 0, 0, 0))(model, rotmats, start.betas, start.camera)
    keypoints = np.concatenate([(np.asarray(xy) + 1) * 112, np.ones((FRAMES, 25, 1))], -1).astype(np.float32)
    keypoints[2, [10, 11, 13, 14, 19, 20, 21, 22, 23, 24], 2] = 0.0
    keypoints[3, :, 2] = 0.0
    keypoints[3, 0, :2] = np.nan  # missing points may also be NaN
    graphdef, state = nnx.split(network)
    return graphdef, state, crops, keypoints, model


@pytest.fixture(scope="module")
def result(problem):
    return fine_tune(*problem, CONFIG)


def test_eft_lowers_the_keypoint_error_of_every_frame(result):
    before, after = np.asarray(result.initial_error_px), np.asarray(result.error_px)
    assert np.all(before[:3] > 3.0) and np.all(after[:3] < 0.6 * before[:3])
    assert before[3] == 0 and after[3] == 0  # no keypoints: no error to report
    assert all(np.all(np.isfinite(np.asarray(a))) for a in result.output)


def test_frames_are_fine_tuned_independently(problem, result):
    """Each frame alone in the batch (repeated to the same shape): the same result as in the vmapped batch."""
    graphdef, state, crops, keypoints, model = problem
    for i in (0, FRAMES - 1):
        alone = fine_tune(graphdef, state, crops[np.full(FRAMES, i)], keypoints[np.full(FRAMES, i)], model, CONFIG)
        for ours, theirs in zip(result.output, alone.output):
            np.testing.assert_allclose(np.asarray(theirs[0]), np.asarray(ours[i]), atol=2e-5)


def test_the_given_weights_are_not_changed(problem, result):
    graphdef, state, crops, keypoints, model = problem
    copy = jax.tree.map(np.array, state)
    fine_tune(graphdef, state, crops, keypoints, model, CONFIG)
    assert jax.tree.all(jax.tree.map(lambda a, b: np.array_equal(np.asarray(a), b), state, copy))


def test_bad_arguments_are_named(problem):
    graphdef, state, crops, keypoints, model = problem
    # fine_tune's own check: unwrapped, since in the test run the annotations' check refuses the shape first
    with pytest.raises(ValueError, match="keypoints"):
        inspect.unwrap(fine_tune)(graphdef, state, crops, keypoints[:, :24], model)
    with pytest.raises(ValueError, match="trainable"):
        EFTConfig(trainable="encoder")


def test_run_with_eft_fits_the_keypoints_better_than_copy_paste(frankmocap_run):
    """``jaxmocap run --integration eft`` on frames 20-23 of the sample clip with random FrankMocap-format weights,
    against copy-and-paste on the same frames."""
    motions = {integration: read_motion(frankmocap_run(integration=integration, end=end) / "motion.npz")
               for integration, end in (("copy-paste", 28), ("eft", 24))}
    for motion in motions.values():
        assert motion["valid"].all() and np.all(np.isfinite(motion["body_pose"]))
    errors = {k: m["reprojection_error_px"][:FRAMES] for k, m in motions.items()}
    assert len(errors["eft"]) == FRAMES and np.all(errors["eft"] < errors["copy-paste"])


def test_eft_needs_the_regressors(tmp_path, capsys):
    code = main(["run", str(CLIP), "--integration", "eft", "--out", str(tmp_path), "--quiet", "--end", "2"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "needs --weights" in err
