"""The hand-written Levenberg-Marquardt fit that `jaxmocap.integrate` used before its optimistix solver, kept for
the side-by-side comparison in ``bench/fit.py`` (``fit_reference``).

Levenberg-Marquardt on the body model with an analytic, matrix-free Jacobian (one body; batch with `jax.vmap`).

Unknowns of one body: the 55 joint axis-angles ``theta`` (a static mask says which are free), ``betas`` and a
similarity camera ``cam = (scale, t_1..t_D)`` mapping model points ``x`` to data ``scale * x[:D] + t`` (D = 2:
weak perspective to pixels; D = 3: metric 3D landmarks up to scale and offset, as IK uses it).

Why not a dense Jacobian: with ~170 unknowns a `jacfwd` costs ~170 forward passes, and forming ``J^T J`` and its
Cholesky for a batch of 1024 costs ~0.6 s per iteration here (measured; see ``bench/fit.py``). Instead:

* The Jacobian is geometric. Rotating joint ``j`` by a world-frame increment ``w_j`` moves a point ``x_k`` carried
  by it by ``w_j x (x_k - p_j)``; ``w_j = G_parent(j) J_l(theta_j) dtheta_j`` with ``J_l`` SO(3)'s left Jacobian.
  A keypoint's dependence on joints is the constant matrix ``reach[k, j]`` (skinning weight of ``k`` on joints
  at or below ``j``), so ``J v`` and ``J^T u`` are two products with one constant (K, 55) matrix shared by the
  whole batch (one GEMM under `vmap`) plus cross products. Shape derivatives are exact for the skeleton
  (``(K, 3, B)`` per body). Pose blend shapes are left out of the Jacobian (not of the residual): they move
  the few vertex keypoints by millimetres.
* The LM step solves the damped normal equations with a fixed number of preconditioned conjugate-gradient
  iterations (block-Jacobi: 3x3 per joint, the shape diagonal, the camera block); the step is accepted or rejected
  on the true robust cost, with Nielsen's damping update.

Residuals: data ``sqrt(conf * rho'(|r|^2)) r`` with a Cauchy robust loss of scale ``robust_scale`` (IRLS), and
priors ``scale_ref * lambda_j (theta_j - theta0_j)``, ``scale_ref * lambda_betas * betas`` and one-sided bending
limits of elbows and knees (priors are in metres: ``scale_ref`` is the initial camera scale).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

import smplx_jax
from smplx_jax import BodyModel, SMPLXParams

# One-sided bending limits (SMPLify-X's angle prior): (joint, axis component, sign): sign * theta[joint, axis] > 0
# is hyper-extension. Elbows bend about y (left negative, right positive), knees about x (positive).
BEND_LIMITS = ((18, 1, 1.0), (19, 1, -1.0), (4, 0, -1.0), (5, 0, -1.0))


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class KeypointModel:
    """A body model reduced to what a fit to ``K`` keypoints needs, precomputed once (see `keypoint_model`)."""

    body: BodyModel  # sparse arrays trimmed to the 21 vertex joints
    index: Float[Array, "K"]  # keypoints as indices into the 127 output joints (int32)
    skin: Float[Array, "K 55"]  # skinning weight of keypoint k on joint l (one-hot for skeleton joints)
    reach: Float[Array, "K 55"]  # sum of skin[k, l] over joints l at or below j
    rest_shapedirs: Float[Array, "3 B K"]  # shape directions of each keypoint's rest point
    ancestors: Float[Array, "55 55"]  # [j, l] = 1 when j is l or an ancestor of l
    joint_shapedirs: Float[Array, "3 B 55"]  # of the rest joints
    parent_shapedirs: Float[Array, "3 B 55"]  # of each joint's parent (the root's own)
    reach2: Float[Array, "K 55"]  # reach ** 2


def _trimmed_body(model: BodyModel) -> BodyModel:
    """The same model with only the vertex-joint vertices kept (landmarks are not fitted)."""
    slots = np.asarray(model.vertex_joint_slots)
    k = np.asarray(model.sparse_ids).shape[0]
    cols = (np.arange(3)[:, None] * k + slots).ravel()  # coordinate-major columns of those vertices
    n = len(slots)
    return dataclasses.replace(
        model,
        sparse_ids=model.sparse_ids[slots],
        sparse_template_cm=model.sparse_template_cm[:, slots],
        sparse_shapedirs_cm=model.sparse_shapedirs_cm[:, cols],
        sparse_posedirs_cm=model.sparse_posedirs_cm[:, cols],
        sparse_skin_joints=model.sparse_skin_joints[:, slots],
        sparse_skin_weights=model.sparse_skin_weights[:, slots],
        vertex_joint_slots=jnp.arange(n, dtype=jnp.int32),
        landmark_slots=jnp.zeros_like(model.landmark_slots),
    )


def keypoint_model(model: BodyModel, index) -> KeypointModel:
    """Precompute the fit's constants for keypoints ``index`` (indices into the 127 output joints; skeleton
    joints 0..54 and vertex joints 55..75)."""
    index = np.asarray(index, dtype=np.int64)
    if index.min() < 0 or index.max() >= 76:
        raise ValueError("keypoint indices must be skeleton joints (0..54) or vertex joints (55..75)")
    parents = model.parents
    nj = len(parents)
    ancestors = np.eye(nj)
    for joint in range(nj):
        j = parents[joint]
        while j >= 0:
            ancestors[j, joint] = 1.0
            j = parents[j]
    vertex_ids = np.asarray(model.sparse_ids)[np.asarray(model.vertex_joint_slots)]
    vertex_weights = np.asarray(model.weights_t)[:, vertex_ids].T  # (21, 55)
    nb = model.num_betas
    joint_sd = np.asarray(model.joint_shapedirs)[..., :nb]  # (55, 3, B)
    ks = np.asarray(model.sparse_ids).shape[0]
    sparse_sd = np.asarray(model.sparse_shapedirs_cm)[:nb].reshape(nb, 3, ks)  # (B, 3, Ksparse)
    skin = np.zeros((len(index), nj))
    rest_sd = np.zeros((len(index), 3, nb))
    for k, i in enumerate(index):
        if i < nj:
            skin[k, i] = 1.0
            rest_sd[k] = joint_sd[i]
        else:
            skin[k] = vertex_weights[i - nj]
            rest_sd[k] = sparse_sd[:, :, int(model.vertex_joint_slots[i - nj])].T
    dtype = model.joint_template.dtype
    f = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    parent_sd = joint_sd[np.maximum(np.asarray(parents), 0)]
    cm = lambda a: f(np.transpose(a, (1, 2, 0)))  # noqa: E731  (N, 3, B) -> (3, B, N)
    return KeypointModel(_trimmed_body(model), jnp.asarray(index, jnp.int32), f(skin), f(skin @ ancestors.T),
                         cm(rest_sd), f(ancestors), cm(joint_sd), cm(parent_sd),
                         f((skin @ ancestors.T) ** 2))


@dataclasses.dataclass(frozen=True)
class SolverConfig:
    """Static settings of one solve (hashable: a change recompiles)."""

    iterations: int = 20
    cg_iterations: int = 8
    robust_scale: float = 0.1  # metres (times the camera scale for pixels)
    prior_global: float = 1e-3  # metres per radian
    prior_body: float = 0.02
    prior_hand: float = 0.005
    prior_betas: float = 0.005  # metres per unit of beta
    prior_bend: float = 0.2
    initial_damping: float = 1e-3


class Linearization(NamedTuple):
    """The model at one point, coordinate-major (``(3, N)``: a batch under `vmap` then multiplies by the constant
    ``reach`` in one GEMM without transposes)."""

    x: Float[Array, "3 K"]  # model keypoints (camera not applied)
    p: Float[Array, "3 55"]  # joint positions
    a: Float[Array, "3 3 55"]  # d(world increment)/d(theta) per joint: G_parent J_l(theta)
    jb: Float[Array, "B 3K"]  # dx/dbetas, row b holds all x then all y then all z


def _mm3(a, b):
    """Batched 3x3 @ 3xN written out by component (XLA fuses it; tiny batched dots are slow on CPU)."""
    return jnp.stack([a[..., i, 0, None] * b[..., 0, :] + a[..., i, 1, None] * b[..., 1, :]
                      + a[..., i, 2, None] * b[..., 2, :] for i in range(3)], axis=-2)


def left_jacobian(rotvec: Float[Array, "... 3"]) -> Float[Array, "... 3 3"]:
    """SO(3)'s left Jacobian ``I + (1 - cos t)/t^2 K + (t - sin t)/t^3 K^2`` (series near zero)."""
    t2 = jnp.sum(rotvec * rotvec, axis=-1)
    small = t2 < 1e-4
    t = jnp.sqrt(jnp.where(small, 1.0, t2))
    t2s = jnp.where(small, 1.0, t2)
    c1 = jnp.where(small, 0.5 - t2 / 24.0, (1.0 - jnp.cos(t)) / t2s)
    c2 = jnp.where(small, 1.0 / 6.0 - t2 / 120.0, (t - jnp.sin(t)) / (t2s * t))
    return smplx_jax.rotations.skew_polynomial(rotvec, c1, c2)


def params_of(theta, betas, num_expression) -> SMPLXParams:
    z = jnp.zeros(3, theta.dtype)
    return SMPLXParams(theta[0], theta[1:22], theta[25:40], theta[40:55], theta[22], theta[23], theta[24], betas,
                       jnp.zeros(num_expression, theta.dtype), z)


def model_keypoints(km: KeypointModel, theta, betas) -> Float[Array, "K 3"]:
    return smplx_jax.forward_joints(km.body, params_of(theta, betas, km.body.num_expression))[km.index]


def linearize(km: KeypointModel, theta, betas) -> Linearization:
    body = km.body
    params = params_of(theta, betas, body.num_expression)
    x = smplx_jax.forward_joints(body, params)[km.index]
    g, p = smplx_jax.posed_skeleton(body, params)
    parents = np.asarray(body.parents)
    g = jnp.transpose(g, (1, 2, 0))  # (3, 3, 55)
    g_parent = jnp.concatenate([jnp.eye(3, dtype=theta.dtype)[:, :, None], g[:, :, parents[1:]]], axis=2)
    a = _ab(g_parent, jnp.transpose(left_jacobian(theta), (1, 2, 0)))
    sd = km.joint_shapedirs  # (3, B, 55)
    nb = sd.shape[1]

    def rot(r, v):  # (3, 3, N) applied to (3, B, N)
        return jnp.stack([r[i, 0, None] * v[0] + r[i, 1, None] * v[1] + r[i, 2, None] * v[2] for i in range(3)])

    e = rot(g_parent, sd - km.parent_shapedirs)  # bone shape directions in the world; the root's is sd[..., 0]
    e = e.at[:, :, 0].set(sd[:, :, 0])
    dp = (e.reshape(3 * nb, 55) @ km.ancestors).reshape(3, nb, 55)  # d(joint position)/d(betas)
    nk = km.index.shape[0]
    g_blend = (g.reshape(9, 55) @ km.skin.T).reshape(3, 3, nk)
    jb = rot(g_blend, km.rest_shapedirs) + ((dp - rot(g, sd)).reshape(3 * nb, 55) @ km.skin.T).reshape(3, nb, nk)
    return Linearization(x.T, p.T, a, jnp.transpose(jb, (1, 0, 2)).reshape(nb, 3 * nk))


class Problem(NamedTuple):
    """Data and prior of one body."""

    target: Float[Array, "K D"]
    conf: Float[Array, "K"]  # 0 = missing
    theta0: Float[Array, "55 3"]  # prior centre (the initial pose)
    prior: Float[Array, "55"]  # prior weight per joint, metres per radian
    scale_ref: Float[Array, ""]  # initial camera scale: pixels (or data units) per metre


def _cr(a, b):
    """Cross product of coordinate-major (3, N) arrays."""
    return jnp.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _av(a, v):  # (3, 3, N) @ (3, N) per column
    return jnp.stack([a[i, 0] * v[0] + a[i, 1] * v[1] + a[i, 2] * v[2] for i in range(3)])


def _atv(a, v):
    return jnp.stack([a[0, i] * v[0] + a[1, i] * v[1] + a[2, i] * v[2] for i in range(3)])


def _ab(a, b):  # (3, 3, N) @ (3, 3, N) per column
    return jnp.stack([jnp.stack([a[i, 0] * b[0, k] + a[i, 1] * b[1, k] + a[i, 2] * b[2, k] for k in range(3)])
                      for i in range(3)])


def _inv3(m):  # (3, 3, N) per column
    a, b, c = m[0, 0], m[0, 1], m[0, 2]
    d, e, f = m[1, 0], m[1, 1], m[1, 2]
    g, h, i = m[2, 0], m[2, 1], m[2, 2]
    co = jnp.stack([jnp.stack([e * i - f * h, c * h - b * i, b * f - c * e]),
                    jnp.stack([f * g - d * i, a * i - c * g, c * d - a * f]),
                    jnp.stack([d * h - e * g, b * g - a * h, a * e - b * d])])
    det = a * co[0, 0] + b * co[1, 0] + c * co[2, 0]
    return co / det


class _Vec(NamedTuple):
    theta: jax.Array  # (3, 55)
    betas: jax.Array  # (B,)
    cam: jax.Array  # (1 + D,)


def _tmap(f, *vs):
    return jax.tree.map(f, *vs)


def _dot(u, v):
    return sum(jnp.vdot(a, b) for a, b in zip(u, v))


class Result(NamedTuple):
    theta: jax.Array
    betas: jax.Array
    cam: jax.Array
    cost: jax.Array
    initial_cost: jax.Array
    accepted: jax.Array  # number of accepted steps


def solve(km: KeypointModel, problem: Problem, theta, betas, cam, free_joints: Float[Array, "55"], fit_betas,
          fit_scale: bool, config: SolverConfig) -> Result:
    """Robust, regularised least squares of one body from ``(theta, betas, cam)``; never increases the cost.
    ``free_joints`` (55,) and ``fit_betas`` are 0/1 masks (bools or traced values: one compiled solver serves
    different free sets)."""
    dtype = theta.dtype
    d = problem.target.shape[-1]
    nk = problem.target.shape[0]
    free = jnp.asarray(free_joints, dtype)[None, :]  # (1, 55)
    mask = _Vec(jnp.broadcast_to(free, (3, 55)), jnp.full(betas.shape, fit_betas, dtype),
                jnp.concatenate([jnp.full((1,), float(fit_scale), dtype), jnp.ones((d,), dtype)]))
    target = problem.target.T  # (D, K)
    theta0 = problem.theta0.T
    sref = problem.scale_ref
    sigma2 = (config.robust_scale * sref) ** 2
    lam_theta = (sref * problem.prior)[None, :] ** 2 * jnp.ones((3, 55), dtype)  # prior Hessian diagonal
    lam_betas = (sref * config.prior_betas) ** 2
    bend_j = np.array([j for j, _, _ in BEND_LIMITS])
    bend_c = np.array([c for _, c, _ in BEND_LIMITS])
    bend_sign = jnp.asarray([sg for _, _, sg in BEND_LIMITS], dtype)
    lam_bend = (sref * config.prior_bend) ** 2

    def residual(lin, cam):
        return cam[0] * lin.x[:d] + cam[1:, None] - target

    def cost_of(theta_cm, betas, lin, cam):
        r = residual(lin, cam)
        data = jnp.sum(problem.conf * sigma2 * jnp.log1p(jnp.sum(r * r, 0) / sigma2))
        bend = jax.nn.relu(bend_sign * theta_cm[bend_c, bend_j])
        prior = (jnp.sum(lam_theta * (theta_cm - theta0) ** 2) + lam_betas * jnp.sum(betas**2)
                 + lam_bend * jnp.sum(bend**2))
        return 0.5 * (data + prior)

    def step(theta_cm, betas, cam, lin, mu):
        r = residual(lin, cam)
        w = problem.conf / (1.0 + jnp.sum(r * r, 0) / sigma2)  # IRLS weights (K,)
        s = cam[0]
        bend_val = bend_sign * theta_cm[bend_c, bend_j]
        bend_on = (bend_val > 0).astype(dtype)
        h_bend = jnp.zeros_like(theta_cm).at[bend_c, bend_j].add(lam_bend * bend_on)
        g_bend = jnp.zeros_like(theta_cm).at[bend_c, bend_j].add(lam_bend * bend_on * bend_val * bend_sign)
        prior_h = _Vec(lam_theta + h_bend, jnp.full_like(betas, lam_betas), jnp.zeros_like(cam))
        pad = jnp.zeros((3 - d, nk), dtype)

        def jv(v):
            omega = _av(lin.a, v.theta)
            dx = _cr(omega @ km.reach.T, lin.x) - _cr(omega, lin.p) @ km.reach.T + (v.betas @ lin.jb).reshape(3, nk)
            return s * dx[:d] + v.cam[0] * lin.x[:d] + v.cam[1:, None]

        def jtu(u):
            f = jnp.concatenate([s * u, pad])
            g_omega = _cr(lin.x, f) @ km.reach - _cr(lin.p, f @ km.reach)
            return _Vec(_atv(lin.a, g_omega), lin.jb @ f.reshape(-1),
                        jnp.concatenate([jnp.sum(u * lin.x[:d])[None], jnp.sum(u, 1)]))

        # Block-Jacobi blocks of J^T W J: 3x3 per joint (from moments of the keypoints: one GEMM), shape, camera.
        x = lin.x
        xx = (x[:, None, :] * x[None, :, :]).reshape(9, nk)
        mom = jnp.concatenate([w[None], w * x, w * xx]) @ km.reach2  # (13, 55)
        m0, m1, m2 = mom[0], mom[1:4], mom[4:].reshape(3, 3, 55)
        pv_ = lin.p
        m1p = m1[:, None, :] * pv_[None, :, :]
        q = m2 - m1p - jnp.swapaxes(m1p, 0, 1) + m0 * (pv_[:, None, :] * pv_[None, :, :])
        if d == 2:
            z = jnp.zeros_like(m0)
            b_omega = jnp.stack([jnp.stack([q[2, 2], z, -q[0, 2]]), jnp.stack([z, q[2, 2], -q[1, 2]]),
                                 jnp.stack([-q[0, 2], -q[1, 2], q[0, 0] + q[1, 1]])])
        else:
            b_omega = (q[0, 0] + q[1, 1] + q[2, 2]) * jnp.eye(3, dtype=dtype)[:, :, None] - q
        b_omega = (s * s) * b_omega
        b_theta = _ab(jnp.swapaxes(lin.a, 0, 1), _ab(b_omega, lin.a))  # (3, 3, 55)
        jbd = lin.jb[:, : d * nk]
        b_betas_diag = (s * s) * jnp.sum(jbd * jbd * jnp.tile(w, d), axis=1)  # shape: diagonal (Jacobi) block
        xd = x[:d]
        wsum = jnp.sum(w)
        b_cam = jnp.concatenate([
            jnp.concatenate([jnp.sum(w * xd * xd)[None], jnp.sum(w * xd, 1)])[None],
            jnp.concatenate([jnp.sum(w * xd, 1)[:, None], wsum * jnp.eye(d, dtype=dtype)], 1)])
        diag_theta = jnp.stack([b_theta[i, i] for i in range(3)])
        diag = _Vec(diag_theta + prior_h.theta, b_betas_diag + prior_h.betas, jnp.diagonal(b_cam))
        damp = _tmap(lambda dg: mu * dg + 1e-9 * (1.0 + dg), diag)

        def hv(v):
            v = _tmap(jnp.multiply, v, mask)
            out = jtu(w * jv(v))
            out = _tmap(lambda o, ph, dm, vv: o + (ph + dm) * vv, out, prior_h, damp, v)
            return _tmap(jnp.multiply, out, mask)

        eye3 = jnp.eye(3, dtype=dtype)[:, :, None]
        extra = prior_h.theta + damp.theta  # (3, 55)
        p_theta = _inv3(b_theta + extra[:, None, :] * eye3)
        p_betas = 1.0 / (diag.betas + damp.betas)
        b_cam = b_cam + jnp.diag(damp.cam)
        p_cam = _inv3(b_cam[:, :, None])[:, :, 0] if d == 2 else jnp.linalg.inv(b_cam)

        def precond(v):
            return _tmap(jnp.multiply, _Vec(_av(p_theta, v.theta), p_betas * v.betas, p_cam @ v.cam), mask)

        grad = jtu(w * r)
        grad = _Vec(grad.theta + lam_theta * (theta_cm - theta0) + g_bend, grad.betas + lam_betas * betas, grad.cam)
        grad = _tmap(jnp.multiply, grad, mask)

        # Preconditioned CG on (H + damping) delta = -grad, from zero.
        res = _tmap(jnp.negative, grad)
        zv = precond(res)
        delta = _tmap(jnp.zeros_like, res)

        def cg(_, carry):
            delta, res, zv, pv, rz = carry
            hp = hv(pv)
            php = _dot(pv, hp)
            alpha = jnp.where(php > 0, rz / jnp.where(php > 0, php, 1.0), 0.0)
            delta = _tmap(lambda a, b: a + alpha * b, delta, pv)
            res = _tmap(lambda a, b: a - alpha * b, res, hp)
            zv = precond(res)
            rz_new = _dot(res, zv)
            beta = jnp.where(rz > 0, rz_new / jnp.where(rz > 0, rz, 1.0), 0.0)
            pv = _tmap(lambda a, b: a + beta * b, zv, pv)
            return delta, res, zv, pv, rz_new

        delta = jax.lax.fori_loop(0, config.cg_iterations, cg, (delta, res, zv, zv, _dot(res, zv)))[0]
        # Predicted decrease of the (damping-free) quadratic model.
        h_delta = hv(delta)
        h_delta = _tmap(lambda hd, dm, dv: hd - dm * dv, h_delta, damp, delta)
        predicted = -(_dot(grad, delta) + 0.5 * _dot(delta, h_delta))
        return delta, predicted

    lin0 = linearize(km, theta, betas)
    theta_cm = theta.T
    cost0 = cost_of(theta_cm, betas, lin0, cam)

    def lm(_, state):
        theta_cm, betas, cam, lin, cost, mu, nu, accepted = state
        delta, predicted = step(theta_cm, betas, cam, lin, mu)
        theta_c, betas_c, cam_c = theta_cm + delta.theta, betas + delta.betas, cam + delta.cam
        lin_c = linearize(km, theta_c.T, betas_c)
        cost_c = cost_of(theta_c, betas_c, lin_c, cam_c)
        gain = (cost - cost_c) / jnp.where(predicted > 0, predicted, 1.0)
        ok = jnp.isfinite(cost_c) & (cost_c < cost) & (cam_c[0] > 0)
        pick = lambda new, old: jax.tree.map(lambda a, b: jnp.where(ok, a, b), new, old)  # noqa: E731
        theta_cm, betas, cam, lin, cost = pick((theta_c, betas_c, cam_c, lin_c, cost_c),
                                               (theta_cm, betas, cam, lin, cost))
        mu = jnp.where(ok, mu * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3), mu * nu)
        nu = jnp.where(ok, 2.0, 2.0 * nu)
        return theta_cm, betas, cam, lin, cost, jnp.clip(mu, 1e-9, 1e9), jnp.minimum(nu, 1e6), accepted + ok

    init = (theta_cm, betas, cam, lin0, cost0, jnp.asarray(config.initial_damping, dtype), jnp.asarray(2.0, dtype),
            jnp.asarray(0, jnp.int32))
    theta_cm, betas, cam, _, cost, _, _, accepted = jax.lax.fori_loop(0, config.iterations, lm, init)
    return Result(theta_cm.T, betas, cam, cost, cost0, accepted)


def _fit_one(km, keypoints, theta, betas, cam, config: SolverConfig):
    from jaxmocap.integrate.fitting import prior_weights
    finite = jnp.all(jnp.isfinite(keypoints), axis=-1)
    conf = jnp.where(finite & (keypoints[:, 2] > 0), keypoints[:, 2], 0.0)
    target = jnp.where(finite[:, None], keypoints[:, :2], 0.0)
    prior = jnp.asarray(prior_weights(config)).at[22:25].set(0.0)
    problem = Problem(target, conf, theta, prior, cam[0])
    free = tuple(j not in (22, 23, 24) for j in range(55))
    out = solve(km, problem, theta, betas, cam, free, True, True, config)
    return out.theta, out.betas, out.cam


_fit_batch = jax.jit(jax.vmap(_fit_one, in_axes=(None, 0, 0, 0, 0, None)), static_argnums=5)


def fit_reference(model, keypoints, theta, betas, cam, config: SolverConfig):
    """The old `fit` on given cameras: (theta (T, 55, 3), betas, cam (T, 3)) in chunks of 64 frames."""
    km = keypoint_model(model, smplx_jax.constants.OPENPOSE67_FROM_SMPLX)
    outs = []
    for start in range(0, keypoints.shape[0], 64):
        s = slice(start, start + 64)
        outs.append(_fit_batch(km, keypoints[s], theta[s], betas[s], cam[s], config))
    return [np.concatenate([np.asarray(o[i]) for o in outs]) for i in range(3)]
