"""The clip fit's start chosen over time. One image leaves each bone's depth ambiguous: its far joint can lie on
either side of its near joint's depth, on the same camera ray (the same pixel) at the bone's length, and a fit
started on the wrong side stays there. Each frame's start gives four hypotheses for each limb (`LIMBS`: its upper
and its lower bone each on its side or the other, `limb_hypotheses`), and each limb's hypotheses are chosen for the
whole clip at once by dynamic programming on the clip fit's own cost (`clip.residuals`): each frame's residuals
(reprojection, the 3D landmarks' bone directions, anatomy) and the motion's, which tie three frames, weighed against
the start's own frame-to-frame noise (`start_jitter`). A limb moves its own keypoints, bones and joints alone, so
each limb's choice is exact given the rest.

    y = chosen_start(y, data, config)  # one clip (`clip.clip_problem`'s start and data), or in its steps:
    unary, triple, hypotheses = hypothesis_costs(y, data, config)  # frame by frame: windows of a long clip
    codes = limb_codes(unary, triple)  # (T, limbs), over the whole clip
    y = y._replace(pose_rotvecs=with_codes(y.pose_rotvecs, hypotheses, codes))
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, Int

from jaxmocap.integrate.clip import (
    SOLVED_JOINTS,
    ClipConfig,
    ClipData,
    ClipUnknowns,
    full_pose,
    keypoints_3d,
    motion_residuals,
    motion_rows,
    residuals,
    shape_of,
)
from jaxmocap.integrate.keypoints import params_of
from smplx_jax import BodyModel, posed_skeleton
from smplx_jax.rotations import rotmat_to_rotvec, rotvec_to_rotmat

# SMPL-X joints of each limb, near to far: the arms (shoulder, elbow, wrist), then the legs (hip, knee, ankle); left
# then right. SOLVED_JOINTS keeps these at their own index.
LIMBS = ((16, 18, 20), (17, 19, 21), (1, 4, 7), (2, 5, 8))
# each code's (upper bone mirrored, lower bone mirrored) in depth; code 0 is the start
CODES = ((False, False), (False, True), (True, False), (True, True))


def _turn(a: Float[Array, "3"], b: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """The least rotation taking the direction of ``a`` onto that of ``b`` (opposite: half a turn about an axis
    across them)."""
    a, b = a / jnp.linalg.norm(a), b / jnp.linalg.norm(b)
    axis = jnp.cross(a, b)
    sine = jnp.linalg.norm(axis)
    across = jnp.cross(a, jnp.eye(3, dtype=a.dtype)[jnp.argmin(jnp.abs(a))])
    unit = jnp.where(sine > 1e-6, axis / jnp.maximum(sine, 1e-12), across / jnp.linalg.norm(across))
    return rotvec_to_rotmat(unit * jnp.arctan2(sine, jnp.dot(a, b)))


def _on_ray(near: Float[Array, "3"], far: Float[Array, "3"], length, other_side: bool) -> Float[Array, "3"]:
    """The point on the camera's ray through ``far`` at ``length`` from ``near`` (camera frame): of the two, the one
    on ``far``'s side of the ray's point nearest ``near``, or the other; that nearest point where the ray passes
    farther than ``length`` from ``near``."""
    ray = far / jnp.linalg.norm(far)
    along = jnp.dot(ray, near)
    across = near - along * ray  # from the ray to ``near`` (not |near|^2 - along^2: metres squared cancel in float32)
    half = jnp.sqrt(jnp.maximum(length**2 - jnp.dot(across, across), 0.0))
    side = jnp.where(jnp.dot(ray, far) >= along, 1.0, -1.0)
    return (along + (-side if other_side else side) * half) * ray


def limb_hypotheses(body: BodyModel, pose: Float[Array, "55 3"], betas: Float[Array, "B"],
                    transl: Float[Array, "3"]) -> Float[Array, "L C 55 3"]:
    """One frame's pose (``transl`` the body's origin in the camera frame) with each of `LIMBS` as each of
    `CODES` says. Each bone's far joint stays on its camera ray (the same pixel) at the bone's length from the near
    joint, on the side of the near joint's depth where it was or on the other (a bone mirrored); the bones are
    turned there by least rotations, and the far joint keeps its rotation in the camera's axes (the hand's or
    foot's own observations decide it)."""
    skeleton = posed_skeleton(body, params_of(pose, betas, body.num_expression).replace(transl=transl))
    g, p = skeleton.glob_rotmats, skeleton.joints
    limbs = []
    for near, middle, far in LIMBS:
        parent = body.parents[near]
        upper, lower = p[middle] - p[near], p[far] - p[middle]
        codes = [pose]
        for mirror_upper, mirror_lower in CODES[1:]:
            bend = _on_ray(p[near], p[middle], jnp.linalg.norm(upper), mirror_upper)
            end = _on_ray(bend, p[far], jnp.linalg.norm(lower), mirror_lower)
            first = _turn(upper, bend - p[near])
            second = _turn(first @ lower, end - bend)
            g_near, g_middle = first @ g[near], second @ first @ g[middle]
            local = jnp.stack([g[parent].T @ g_near, g_near.T @ g_middle, g_middle.T @ g[far]])
            codes.append(pose.at[jnp.asarray([near, middle, far])].set(rotmat_to_rotvec(local)))
        limbs.append(jnp.stack(codes))
    return jnp.stack(limbs)


def start_jitter(y: ClipUnknowns, data: ClipData, config: ClipConfig) -> Float[Array, "M"]:
    """Each motion residual's scale in the start ``y``, at least 1: its robust standard deviation over the frames
    where it counts (1.4826 times the median absolute value). A start made frame by frame (each frame's landmarks)
    shakes from frame to frame far beyond the motion's standard deviations; that noise, which the fit smooths
    away, must not choose the hypotheses, so the motion's residuals weigh against it."""
    rows = motion_rows(data)
    start = motion_residuals(keypoints_3d(y, data), y.pose_rotvecs, rows, data.fps, config, data.scene_from_camera)
    counted = jnp.concatenate([jnp.repeat(rows, 3, 1), jnp.repeat(rows[:, :1], start.shape[1] - 3 * rows.shape[1], 1)],
                              1)
    spread = 1.4826 * jnp.nanmedian(jnp.where(counted > 0, jnp.abs(start), jnp.nan), 0)
    return jnp.maximum(jnp.where(jnp.isnan(spread), 1.0, spread), 1.0)


def hypothesis_costs(y: ClipUnknowns, data: ClipData, config: ClipConfig
                     ) -> tuple[Float[Array, "T L C"], Float[Array, "T L C C C"], Float[Array, "T L C 3 3"]]:
    """Each frame's `limb_hypotheses` of the start ``y`` (each limb's three joints' rotations, axis-angles) and
    their costs in the clip fit's objective: ``unary[t, l, c]`` half the squares of frame t's residuals with limb l
    as code c (the rest as started), ``triple[t, l, a, b, c]`` of its motion's with limb l as a, b and c in frames
    t - 1, t and t + 1 (zero in the first and last frames; over `start_jitter`). Frames where the person is not
    found keep their start (infinite cost for the other codes)."""
    pose = jax.vmap(full_pose)(y.pose_rotvecs, data.fixed_pose)
    full = jax.vmap(limb_hypotheses, in_axes=(None, 0, None, 0))(data.km.body, pose, shape_of(y, data), y.transl)
    hypotheses = full[..., list(SOLVED_JOINTS), :]  # (T, L, C, 52, 3)

    def variant(pose_rotvecs):  # the clip with one limb's code: its frames' costs, keypoints and rotations
        z = y._replace(pose_rotvecs=pose_rotvecs)
        return 0.5 * jnp.sum(residuals(z, data, config).frames ** 2, -1), keypoints_3d(z, data)

    each = jax.vmap(jax.vmap(variant, in_axes=1), in_axes=1)  # over limbs, then codes
    unary, x = each(hypotheses)  # (L, C, T), (L, C, T, 67, 3)
    rotations = jnp.moveaxis(hypotheses, 0, 2)  # (L, C, T, 52, 3)
    rows = motion_rows(data)
    scale = start_jitter(y, data, config)

    def triple(xa, xb, xc, ra, rb, rc):  # the motion's cost in each frame with codes a, b, c in it and beside it
        if xa.shape[0] < 3:
            return jnp.zeros(xa.shape[:1], xa.dtype)
        threes = [jnp.stack([a[:-2], b[1:-1], c[2:]], 1)
                  for a, b, c in ((xa, xb, xc), (ra, rb, rc), (rows,) * 3, (data.scene_from_camera,) * 3)]
        middle = jax.vmap(lambda x3, r3, w3, s3: motion_residuals(x3, r3, w3, data.fps, config, s3)[1])(
            *threes) / scale
        zero = jnp.zeros((1,), xa.dtype)
        return jnp.concatenate([zero, 0.5 * jnp.sum(middle**2, -1), zero])

    over_c = jax.vmap(triple, in_axes=(None, None, 0, None, None, 0))
    over_bc = jax.vmap(over_c, in_axes=(None, 0, None, None, 0, None))
    over_abc = jax.vmap(over_bc, in_axes=(0, None, None, 0, None, None))
    motion = jax.vmap(lambda xl, rl: over_abc(xl, xl, xl, rl, rl, rl))(x, rotations)  # (L, a, b, c, T)
    codes = jnp.arange(len(CODES))
    unary = jnp.where((data.found[None, None] > 0) | (codes[None, :, None] == 0), unary, jnp.inf)
    unary = jnp.where(jnp.isnan(unary), jnp.inf, unary)
    turns = jnp.stack([hypotheses[:, limb][:, :, list(joints)] for limb, joints in enumerate(LIMBS)], 1)
    return jnp.moveaxis(unary, -1, 0), jnp.moveaxis(motion, -1, 0), turns


def best_codes(unary: Float[ArrayLike, "T C"], triple: Float[ArrayLike, "T C C C"]) -> Int[Array, "T"]:
    """The codes minimising ``sum_t unary[t, c_t] + triple[t, c_t-1, c_t, c_t+1]`` over the whole clip (Viterbi
    on pairs of frames; ``triple`` zero in the first and last frames)."""
    unary, triple = jnp.asarray(unary), jnp.asarray(triple)
    frames, count = unary.shape
    if frames < 3:
        return jnp.argmin(unary, -1)
    first = unary[0][:, None] + unary[1][None, :]  # (code at t - 1, code at t)

    def forward(value, step):
        motion, next_unary = step
        total = value[:, :, None] + motion + next_unary[None, None, :]
        return jnp.min(total, 0), jnp.argmin(total, 0)

    last, back = jax.lax.scan(forward, first, (triple[1:-1], unary[2:]))
    pair = jnp.argmin(last.reshape(-1))
    end = (pair // count, pair % count)

    def backward(codes, pointers):  # one-hot picks, not gathers (those fail under x64 in a jitted scan)
        b, c = codes
        a = jnp.sum(pointers * jax.nn.one_hot(b, count)[:, None] * jax.nn.one_hot(c, count)[None, :]).astype(b.dtype)
        return (a, b), a

    _, earlier = jax.lax.scan(backward, end, back, reverse=True)
    return jnp.concatenate([earlier, jnp.stack(end)])


def limb_codes(unary: Float[ArrayLike, "T L C"], triple: Float[ArrayLike, "T L C C C"]) -> Int[Array, "T L"]:
    """`best_codes` of each limb."""
    return jax.vmap(best_codes, in_axes=1, out_axes=1)(unary, triple)


def with_codes(pose_rotvecs: Float[ArrayLike, "T 52 3"], hypotheses: Float[ArrayLike, "T L C 3 3"],
               codes: Int[ArrayLike, "T L"]) -> Float[Array, "T 52 3"]:
    """`SOLVED_JOINTS`' rotations with each limb's joints as its code in each frame picks (`hypothesis_costs`'
    hypotheses)."""
    pose_rotvecs, hypotheses = jnp.asarray(pose_rotvecs), jnp.asarray(hypotheses)
    pick = jax.nn.one_hot(codes, len(CODES), dtype=hypotheses.dtype)  # (T, L, C)
    chosen = jnp.einsum("tlc,tlcjk->tljk", pick, hypotheses)
    for limb, joints in enumerate(LIMBS):
        pose_rotvecs = pose_rotvecs.at[:, list(joints)].set(chosen[:, limb])
    return pose_rotvecs


def chosen_start(y: ClipUnknowns, data: ClipData, config: ClipConfig) -> ClipUnknowns:
    """The start ``y`` of one clip with each limb's hypotheses chosen over the whole clip (module docstring)."""
    unary, triple, hypotheses = hypothesis_costs(y, data, config)
    codes = limb_codes(unary, triple)
    return y._replace(pose_rotvecs=with_codes(y.pose_rotvecs, hypotheses, codes))

