"""One body's robust, regularised least squares: its unknowns, residuals and priors (`levenberg_marquardt` solves
it).

Unknowns (`Unknowns`): the 55 joint axis-angles, ``betas`` and a camera ``(log scale, t_1..t_D)`` mapping model
points ``x`` to data ``(scale * x[:D] + t - c) / (1 + scale * x[2] / f) + c`` (`project`). D = 2, the 2D fit:
pixels through a pinhole camera of focal length ``f`` and principal point ``c`` (the body's origin at depth
``f / scale``), or weak perspective where ``1 / f = 0``; D = 3, IK: metric 3D landmarks up to scale and offset
(``1 / f = 0``, ``c = 0``). `Problem` says which joints (and whether the shape) are free.

Residuals (`residuals`; half their sum of squares is the cost):

* data: ``sqrt(conf) * r * sqrt(log1p(u) / u)`` per keypoint, ``r`` its error and ``u = |r|^2 / sigma^2``, whose
  square is Cauchy's robust ``conf * sigma^2 * log1p(u)``; ``sigma = robust_scale * scale_ref``;
* priors, in metres times ``scale_ref`` (the initial camera scale, pixels or data units per metre): each joint
  near its start ``prior[j] * (theta_j - theta0_j)`` (per axis, `prior_weights`), shape ``prior_betas * betas``,
  and one-sided joint limits ``weight * relu(sign * theta[j, axis] - slack)`` (`BEND_LIMITS`; ``prior_bend`` for
  elbows, knees and fingers bent backwards, ``prior_finger_range`` for the fingers' range).

`levenberg_marquardt.solve` minimises the cost.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from jaxmocap.integrate import keypoints
from jaxmocap.integrate.keypoints import KeypointModel

# One-sided joint limits (SMPLify-X's angle prior, and the fingers'): (joint, axis component, sign, slack):
# sign * theta[joint, axis] > slack (radians) is beyond the limit. Elbows bend about y (left negative, right
# positive), knees about x (positive); the three joints of index, middle, pinky and ring fingers about z (left
# negative, right positive), not backwards (some slack: a flat hand, where fits often start, sits on that
# limit); their range (`_FINGER_RANGE`, weighted by ``prior_finger_range``): flexed up to 100 degrees, and only
# the knuckles sideways (about y), by up to 20 degrees.
FINGER_JOINTS = tuple(range(12))  # of each hand's 15: index, middle, pinky, ring; not the thumb
FINGER_BACKWARDS = tuple((first + k, 2, -flex) for first, flex in ((25, -1.0), (40, 1.0)) for k in FINGER_JOINTS)
_FINGER_RANGE = tuple((j, axis, -sign, 1.75) for j, axis, sign in FINGER_BACKWARDS) + tuple(
    (first + k, 1, sign, 0.35) for first in (25, 40) for k in FINGER_JOINTS[::3] for sign in (1.0, -1.0))
BEND_LIMITS = ((18, 1, 1.0, 0.0), (19, 1, -1.0, 0.0), (4, 0, -1.0, 0.0), (5, 0, -1.0, 0.0)) + tuple(
    (j, axis, sign, 0.1) for j, axis, sign in FINGER_BACKWARDS) + _FINGER_RANGE
# Radians inside a limit within which the solver's model keeps the limit's stiffness once a refused step crossed it
# (`levenberg_marquardt`): the one-sided term has no curvature until crossed, so steps from just inside it landed
# far beyond, were refused, and fits pressed against a finger's limit crawled (docs/BENCHMARKS.md).
BEND_MARGIN = 0.03
_BEND_JOINT, _BEND_AXIS, _BEND_SIGN, _BEND_SLACK = (list(c) for c in zip(*BEND_LIMITS))  # lists: no cached dtypes


def bend_weights(config, dtype=np.float32) -> np.ndarray:
    """The weight of each of `BEND_LIMITS`, metres per radian, in ``dtype`` (the pose's: a float32 weight would
    round a float64 fit's terms to float32 when the scale it multiplies is weakly typed)."""
    return np.where(np.arange(len(BEND_LIMITS)) < len(BEND_LIMITS) - len(_FINGER_RANGE), config.prior_bend,
                    config.prior_finger_range).astype(dtype)


def bend_of(pose: Float[Array, "55 3"]) -> Float[Array, "L"]:
    """``sign * theta[joint, axis] - slack`` of each bending limit: positive is hyper-extension."""
    return jnp.asarray(_BEND_SIGN, pose.dtype) * pose[_BEND_JOINT, _BEND_AXIS] - jnp.asarray(_BEND_SLACK, pose.dtype)


@dataclasses.dataclass(frozen=True)
class SolverConfig:
    """Static settings of one solve (hashable: a change recompiles)."""

    iterations: int = 20  # the cap on steps (each evaluates the model once and solves one damped system)
    linear_solver: str = "cholesky"  # or "cg": how each step's system is solved (`levenberg_marquardt`)
    cg_iterations: int = 8  # with "cg"
    joints: tuple[int, ...] | None = None  # the joints the solve moves (None: all 55); the others keep their start
    tolerance: float | None = None  # converged below this predicted relative decrease (None: 1e-5, 1e-10 in float64)
    robust_scale: float = 0.1  # metres (times the camera scale for pixels)
    prior_global: float = 1e-3  # metres per radian
    prior_body: float = 0.02
    prior_hand: float = 0.005
    prior_finger_hinge: float = 0.005  # index to ring fingers off their flexion axis (`prior_weights`)
    prior_thumb: float = 0.005
    prior_betas: float = 0.005  # metres per unit of beta
    prior_bend: float = 0.2
    prior_finger_range: float = 0.0  # the fingers' range of motion (`BEND_LIMITS`)
    initial_damping: float = 1e-2  # Marquardt's mu at the start (relative to the diagonal of J^T J)


class Unknowns(NamedTuple):
    """What a solve moves: the 55 joints' axis-angles, the shape, the camera (`project`)."""

    pose_rotvecs: Float[Array, "55 3"]
    betas: Float[Array, "B"]
    camera: Float[Array, "C"]  # log scale, then the D translations


class Problem(NamedTuple):
    """Data, prior and free set of one body (all arrays: one compiled solver serves different free sets)."""

    km: KeypointModel
    target: Float[Array, "K D"]
    conf: Float[Array, "K"]  # 0 = missing
    pose0: Float[Array, "55 3"]  # prior centre, and the pose of joints that are not free
    betas0: Float[Array, "B"]  # the shape when it is not free
    prior: Float[Array, "55 3"]  # prior weight per joint and axis, metres per radian (`prior_weights`)
    scale_ref: Float[Array, ""]  # pixels (or data units) per metre
    free: Float[Array, "55"]  # 1 = joint free
    fit_betas: Float[Array, ""]  # 1 = shape free
    inv_focal: Float[Array, ""]  # 1 / focal length (pixels); 0: weak perspective (and IK)
    center: Float[Array, "D"]  # principal point (pixels); 0 for IK


class Residuals(NamedTuple):
    """The residuals of one body (`residuals`), each in its unit (module docstring)."""

    data: Float[Array, "D K"]
    pose: Float[Array, "55 3"]
    betas: Float[Array, "B"]
    bend: Float[Array, "L"]  # one per bending limit


def prior_weights(config: SolverConfig) -> np.ndarray:
    """``(55, 3)`` metres per radian: the global orientation, the body (jaw and eyes, which no keypoint sees,
    stay where they start), the hands. Index to ring fingers are hinges, which keypoints alone do not make them:
    their twist about the bone (SMPL-X's x in the rest pose), and sideways bending (y) but at the knuckle, keep
    to the start by ``prior_finger_hinge``; the thumbs' two outer joints (hinges whose axes are not the model's)
    by ``prior_thumb`` (neither less than ``prior_hand``)."""
    prior = np.full((55, 3), config.prior_body, np.float32)
    prior[0] = config.prior_global
    prior[25:55] = config.prior_hand
    hinge, thumb = max(config.prior_finger_hinge, config.prior_hand), max(config.prior_thumb, config.prior_hand)
    for first in (25, 40):
        fingers = first + np.asarray(FINGER_JOINTS)
        prior[fingers, 0] = hinge
        prior[fingers[np.asarray(FINGER_JOINTS) % 3 > 0], 1] = hinge
        prior[first + 13:first + 15] = thumb  # the thumb's base (12) moves freely
    return prior


def log1p_ratio(u):
    """``log1p(u) / u``, smooth at zero."""
    small = u < 1e-3
    us = jnp.where(small, 1.0, u)
    return jnp.where(small, 1.0 - u / 2 + u * u / 3 - u**3 / 4, jnp.log1p(us) / us)


@jax.custom_jvp
def _sqrt_weight(conf):
    """``sqrt(conf)`` whose derivative is zero at zero (an unseen keypoint contributes nothing, to any order)."""
    return jnp.sqrt(conf)


@_sqrt_weight.defjvp
def _sqrt_weight_jvp(primals, tangents):
    (conf,), (dconf,) = primals, tangents
    root = jnp.sqrt(conf)
    return root, jnp.where(conf > 0, 0.5 / jnp.where(conf > 0, root, 1.0), 0.0) * dconf


def pose_and_shape(y: Unknowns, problem: Problem):
    """The pose and shape ``y`` stands for: the problem's own where a joint or the shape is not free."""
    pose = jnp.where(problem.free[:, None] > 0, y.pose_rotvecs, problem.pose0)
    return pose, jnp.where(problem.fit_betas > 0, y.betas, problem.betas0)


def project(x: Float[Array, "3 K"], camera: Float[Array, "C"], problem: Problem):
    """The keypoints' data points ``(D, K)``, and each one's depth relative to the body origin's ``(K,)``."""
    d = problem.target.shape[1]
    center = problem.center[:, None]
    depth = jnp.maximum(1.0 + problem.inv_focal * jnp.exp(camera[0]) * x[2], 0.1)  # never behind the camera
    return (jnp.exp(camera[0]) * x[:d] + camera[1:, None] - center) / depth + center, depth


def cauchy_u(r, problem: Problem, config: SolverConfig):
    """``u = |r|^2 / sigma^2`` per keypoint, ``sigma = robust_scale * scale_ref``."""
    return jnp.sum(r * r, 0) / (config.robust_scale * problem.scale_ref) ** 2


def residuals(y: Unknowns, problem: Problem, config: SolverConfig) -> Residuals:
    """The residuals whose half sum of squares is the cost (the function optimistix minimises)."""
    pose, betas = pose_and_shape(y, problem)
    r = project(keypoints.keypoints_cm(problem.km, pose, betas), y.camera, problem)[0] - problem.target.T
    sref = problem.scale_ref
    return Residuals(_sqrt_weight(problem.conf) * r * jnp.sqrt(log1p_ratio(cauchy_u(r, problem, config))),
                     sref * problem.prior * (pose - problem.pose0), sref * config.prior_betas * betas,
                     sref * bend_weights(config, pose.dtype) * jax.nn.relu(bend_of(pose)))


def prior_quadratic(pose, betas, camera, problem: Problem, config: SolverConfig, stiff=None
                    ) -> tuple[Unknowns, Unknowns]:
    """The gradient and the (Gauss-Newton, diagonal) Hessian of the priors' half sum of squares; ``stiff`` (L,)
    bool: limits whose stiffness the Hessian holds within `BEND_MARGIN` inside them too."""
    sref = problem.scale_ref
    pose_weight = (sref * problem.prior) ** 2
    bend_weight, bend = (sref * bend_weights(config, pose.dtype)) ** 2, bend_of(pose)
    gradient = (pose_weight * (pose - problem.pose0)).at[_BEND_JOINT, _BEND_AXIS].add(
        bend_weight * jax.nn.relu(bend) * jnp.asarray(_BEND_SIGN, pose.dtype))
    held = bend > 0 if stiff is None else (bend > 0) | (stiff & (bend > -BEND_MARGIN))
    hessian = pose_weight.at[_BEND_JOINT, _BEND_AXIS].add(bend_weight * held)
    betas_weight = jnp.full_like(betas, (sref * config.prior_betas) ** 2)
    return (Unknowns(gradient, betas_weight * betas, jnp.zeros_like(camera)),
            Unknowns(hessian, betas_weight, jnp.zeros_like(camera)))
