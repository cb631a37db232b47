"""Integration of body and hands into one SMPL-X body per frame (FrankMocap section 3.3), batched over frames, and
of each person's whole clip as one fit, standing on the floor.

    from jaxmocap.integrate import copy_paste, fit, fit_frame, smooth_params
    params = jax.vmap(copy_paste, in_axes=(None, 0, 0, 0, 0, 0))(model, body, lhand, lwrist, rhand, rwrist)
    result = fit(model, keypoints, init=params)        # keypoints (T, 67, 3) OpenPose order, pixels
    one = fit_frame(model, keypoints[0], init_0)       # one frame: pure, jit/vmap/grad (implicit differentiation)
    clip = fit_clip(model, keypoints, init, focal_length=f, principal_point=c, fps=60.0, keypoint_sigma_px=sigma)
    smoothed = smooth_params(result.params, result.valid)

Modules: `copy_and_paste` (wrist conversion), `inverse_kinematics` (3D landmarks -> pose), `fitting` (2D keypoints ->
pose, shape, camera), `clip` (one person's whole clip as one problem: one shape, the 3D landmarks and the motion in
every frame) with `clip_solver` (its matrix-free solver), `banded` (block-banded systems over frames), `clip_start`
(each limb's depth in its start chosen over the whole clip), `hand_clip` (one hand's frames as one problem, for hands on
their own) and `keypoint_start` (a start from 2D keypoints alone: the default pose turned as the torso shows),
`least_squares` (one body's robust least squares), `levenberg_marquardt` (its optimistix solver: dense or CG steps, a
stopping rule), `keypoints` (model keypoints with an analytic Jacobian), `mat3` (3x3 kernels), `ground` (the floor, the
feet's contacts, the world frame), `hand_fit` (a hand on its own: IK and fit), `eft` (exemplar fine-tuning of the body
regressor), `smooth` (temporal), `camera`, `motion_arrays` (fits -> motion.npz arrays), `synthetic` (problems with known
answers for tests and benchmarks).
"""

from jaxmocap.integrate.camera import project, weak_perspective_from_points
from jaxmocap.integrate.clip import ClipConfig, ClipGround, ClipResult, fit_clip
from jaxmocap.integrate.copy_and_paste import copy_paste, wrist_local_rotvecs
from jaxmocap.integrate.eft import EFTConfig, EFTResult, fine_tune
from jaxmocap.integrate.fitting import FitConfig, FitResult, default_pose, fit, fit_frame
from jaxmocap.integrate.hand_clip import HandClipResult, fit_hand_clip
from jaxmocap.integrate.inverse_kinematics import body_from_blazepose, hand_into_body, ik
from jaxmocap.integrate.motion_arrays import fitted_motion, reprojection_errors
from jaxmocap.integrate.smooth import KERNEL, smooth_camera, smooth_linear, smooth_params, smooth_rotvecs

__all__ = [
    "ClipConfig", "ClipGround", "ClipResult", "EFTConfig", "EFTResult", "FitConfig", "FitResult", "HandClipResult",
    "KERNEL", "body_from_blazepose", "copy_paste", "default_pose", "fine_tune", "fit", "fit_clip", "fit_frame",
    "fit_hand_clip",
    "fitted_motion", "hand_into_body", "ik", "project", "reprojection_errors", "smooth_camera", "smooth_linear",
    "smooth_params", "smooth_rotvecs", "weak_perspective_from_points", "wrist_local_rotvecs",
]
