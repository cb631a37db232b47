"""`jaxmocap.integrate.clip_start`: each limb's depth chosen over the whole clip before the clip fit, on the
synthetic clips of `test_clip_fit`."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np

from jaxmocap.integrate import clip, clip_start
from jaxmocap.integrate.keypoints import params_of
from test_clip_fit import CENTRE, FOCAL, FPS, MODEL, fitted, keypoints_3d, start_of, synthetic_clip


def test_the_dynamic_programme_finds_the_cheapest_sequence():
    """`best_codes` against every sequence of codes of a small random problem."""
    rng = np.random.default_rng(0)
    frames, count = 6, 3
    unary = rng.uniform(size=(frames, count))
    triple = rng.uniform(size=(frames, count, count, count))
    triple[[0, -1]] = 0.0

    def cost(codes):
        return sum(unary[t, codes[t]] for t in range(frames)) + sum(
            triple[t, codes[t - 1], codes[t], codes[t + 1]] for t in range(1, frames - 1))

    best = min(itertools.product(range(count), repeat=frames), key=cost)
    assert tuple(np.asarray(clip_start.best_codes(jnp.asarray(unary), jnp.asarray(triple)))) == best


def test_each_limb_hypothesis_keeps_its_joints_pixels_and_bone_lengths():
    """Every code of every limb puts the middle and far joints on their own pixels at the bones' lengths, the
    middle joint on the other side of the near joint's depth where the code mirrors the upper bone."""
    pose, betas, transl, _, _ = synthetic_clip(2)
    betas = jnp.asarray(betas, jnp.float32)
    hypotheses = clip_start.limb_hypotheses(MODEL, jnp.asarray(pose[1], jnp.float32), betas,
                                            jnp.asarray(transl[1], jnp.float32))

    def joints(p):
        from smplx_jax import posed_skeleton

        return np.asarray(posed_skeleton(MODEL, params_of(p, betas, MODEL.num_expression).replace(
            transl=jnp.asarray(transl[1], jnp.float32))).joints, np.float64)

    start = joints(jnp.asarray(pose[1], jnp.float32))
    for limb, (near, middle, far) in enumerate(clip_start.LIMBS):
        for code, mirrored in enumerate(clip_start.CODES):
            x = joints(hypotheses[limb, code])
            pixels = FOCAL * x[[middle, far], :2] / x[[middle, far], 2:]
            np.testing.assert_allclose(pixels, FOCAL * start[[middle, far], :2] / start[[middle, far], 2:], atol=0.05)
            for a, b in ((near, middle), (middle, far)):
                assert abs(np.linalg.norm(x[b] - x[a]) - np.linalg.norm(start[b] - start[a])) < 1e-4
            ray = start[middle] / np.linalg.norm(start[middle])
            across = 2 * abs(ray @ (start[middle] - start[near]))  # between the ray's two points at the bone's length
            assert abs(np.linalg.norm(x[middle] - start[middle]) - (across if mirrored[0] else 0.0)) < 1e-3


def test_a_limb_turned_in_depth_for_a_few_frames_is_chosen_back():
    """A start (and the 3D landmarks, as a landmark model's depth turns a limb round for a while) with the left leg
    mirrored in depth in six frames of twelve: fitted from that start the clip stays near that local minimum
    (centimetres to decimetres off, as the steps' path goes); from the start chosen over time it comes back within
    centimetres everywhere, several times closer on average."""
    pose, betas, transl, keypoints, directions = synthetic_clip(12)
    start = start_of(pose, transl, 0.003).replace(betas=jnp.broadcast_to(jnp.asarray(betas, jnp.float32), (12, 10)))
    full = jax.vmap(lambda p: p.full_pose())(start)
    turned = jax.vmap(clip_start.limb_hypotheses, in_axes=(None, 0, None, 0))(
        MODEL, full, start.betas[0], start.transl)[:, 2, 3]  # the left leg, both bones mirrored
    flipped = np.zeros(12, bool)
    flipped[3:9] = True
    full = jnp.where(flipped[:, None, None], turned, full)
    start = jax.vmap(params_of, in_axes=(0, 0, None))(full, start.betas, MODEL.num_expression).replace(
        transl=start.transl)
    seen = keypoints_3d(start)
    a, b = (np.asarray(side) for side in zip(*clip.BONES))
    landmarks = (seen[:, b] - seen[:, a]) / np.linalg.norm(seen[:, b] - seen[:, a], axis=-1, keepdims=True)
    directions = np.where(flipped[:, None, None], landmarks, directions)
    y, data = clip.clip_problem(MODEL, keypoints, start, focal_length=FOCAL, principal_point=CENTRE, fps=FPS,
                                keypoint_sigma_px=np.full((12, 67), 0.5), directions=directions,
                                direction_weight=np.ones(directions.shape[:2]), fit_betas=False)
    chosen = jax.jit(clip_start.chosen_start, static_argnums=2)(y, data, clip.ClipConfig())
    chosen = jax.vmap(params_of, in_axes=(0, 0, None))(
        jax.vmap(clip.full_pose)(chosen.pose_rotvecs, data.fixed_pose), start.betas, MODEL.num_expression).replace(
        transl=chosen.transl)
    truth = keypoints_3d(jax.vmap(params_of, in_axes=(0, None, None))(
        jnp.asarray(pose, jnp.float32), jnp.asarray(betas, jnp.float32), MODEL.num_expression).replace(
        transl=jnp.asarray(transl, jnp.float32)))

    def error_mm(s):
        return 1000 * np.max(np.linalg.norm(keypoints_3d(fitted(keypoints, s, directions, False).params) - truth,
                                            axis=-1), -1)

    from_start, from_chosen = error_mm(start), error_mm(chosen)
    assert from_start.mean() > 2 * from_chosen.mean(), (from_start, from_chosen)  # the local minimum it is for
    assert from_chosen.max() < 25.0, from_chosen
