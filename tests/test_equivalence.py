"""smplx_jax.forward against the PyTorch ``smplx`` package on the default model and a random official-shaped
model, over 24 random bodies with large rotations, for each hand-pose convention of ``smplx``."""

import jax
import numpy as np
import pytest
import smplx
import torch

import smplx_jax
from conftest import load
from params_util import random_params, torch_inputs

BATCH = 24
TOL = 1e-5
NUM_PCA = 12
FORWARD = jax.jit(jax.vmap(smplx_jax.forward, in_axes=(None, 0)))
JOINTS = jax.jit(jax.vmap(smplx_jax.forward_joints, in_axes=(None, 0)))


def _vmap_hand(fn):
    return jax.vmap(fn, in_axes=(None, 0, None))


def _torch_model(model_dir, **options):
    return smplx.create(str(model_dir), model_type="smplx", num_betas=10, num_expression_coeffs=10,
                        batch_size=BATCH, **options)


def _hand_inputs(model, params, convention, rng):
    """(our absolute hand poses, smplx's hand inputs) for one convention."""
    if convention == "flat":
        return params, {}
    if convention == "mean":
        rel = {s: _vmap_hand(smplx_jax.hand_pose_to_relative)(model, getattr(params, f"{s}_hand_pose"), s)
               for s in ("left", "right")}
        return params, {f"{s}_hand_pose": v for s, v in rel.items()}
    coeffs = {s: rng.normal(0, 1.0, (BATCH, NUM_PCA)).astype(np.float32) for s in ("left", "right")}
    absolute = {s: _vmap_hand(smplx_jax.hand_pose_from_pca)(model, coeffs[s], s) for s in coeffs}
    if convention == "pca_flat":  # smplx adds no mean: our absolute pose is the mean-relative one
        absolute = {s: _vmap_hand(smplx_jax.hand_pose_to_relative)(model, a, s) for s, a in absolute.items()}
    ours = params.replace(left_hand_pose=absolute["left"], right_hand_pose=absolute["right"])
    return ours, {f"{s}_hand_pose": c for s, c in coeffs.items()}


CONVENTIONS = {
    "flat": dict(use_pca=False, flat_hand_mean=True),
    "mean": dict(use_pca=False, flat_hand_mean=False),
    "pca": dict(use_pca=True, num_pca_comps=NUM_PCA, flat_hand_mean=False),
    "pca_flat": dict(use_pca=True, num_pca_comps=NUM_PCA, flat_hand_mean=True),
}


@pytest.mark.parametrize("convention", list(CONVENTIONS))
def test_forward_matches_smplx(model_dir, convention):
    model = load(model_dir)
    seed = list(CONVENTIONS).index(convention)
    params, hands = _hand_inputs(model, random_params(seed, BATCH), convention, np.random.default_rng(seed))
    with torch.no_grad():
        ref = _torch_model(model_dir, **CONVENTIONS[convention])(**torch_inputs(params, **hands), return_verts=True)
    out = FORWARD(model, params)
    assert out.joints.shape == (BATCH, 127, 3)
    vertex_err = np.abs(np.asarray(out.vertices) - ref.vertices.numpy()).max()
    joint_err = np.abs(np.asarray(out.joints) - ref.joints.numpy()).max()
    print(f"{model_dir.name} {convention}: max |dv| {vertex_err:.2e}, max |dj| {joint_err:.2e}")
    assert vertex_err <= TOL and joint_err <= TOL
    np.testing.assert_allclose(np.asarray(JOINTS(model, params)), np.asarray(out.joints), rtol=0, atol=TOL)


def test_equivalence_detects_a_wrong_model(random_model_dir, default_model_dir):
    """The comparison is not vacuous: another model's output differs far beyond the tolerance."""
    params = random_params(seed=1, batch=BATCH)
    with torch.no_grad():
        ref = _torch_model(random_model_dir, use_pca=False, flat_hand_mean=True)(**torch_inputs(params))
    out = FORWARD(load(default_model_dir), params)
    assert np.abs(np.asarray(out.joints) - ref.joints.numpy()).max() > 100 * TOL


def test_dense_skinning_weights_match_smplx(tmp_path):
    """A file whose vertices all weigh every joint takes the dense skinning product (not the per-vertex gather)."""
    from random_model import random_model_arrays
    from smplx_jax.forward import MAX_GATHERED_JOINTS
    arrays = random_model_arrays(seed=3)
    arrays["weights"] = np.random.default_rng(3).dirichlet(np.ones(arrays["weights"].shape[1]), len(arrays["weights"]))
    (tmp_path / "smplx").mkdir()
    np.savez(tmp_path / "smplx" / "SMPLX_NEUTRAL.npz", **arrays)
    model = smplx_jax.load_model(tmp_path / "smplx" / "SMPLX_NEUTRAL.npz")
    assert model.skin_joints.shape[0] > MAX_GATHERED_JOINTS
    params = random_params(seed=4, batch=BATCH)
    with torch.no_grad():
        ref = _torch_model(tmp_path, use_pca=False, flat_hand_mean=True)(**torch_inputs(params), return_verts=True)
    out = FORWARD(model, params)
    assert np.abs(np.asarray(out.vertices) - ref.vertices.numpy()).max() <= TOL
    assert np.abs(np.asarray(out.joints) - ref.joints.numpy()).max() <= TOL
