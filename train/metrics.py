"""Evaluation metrics in numpy, per example with a mask (big_vision style), and the hand benchmarks' PCK protocol.

    errors = joint_errors(pred_mm, gt_mm)                      # (N, J)
    auc = pck_auc(errors, 20.0, 50.0, mask)                    # STB / RHD: 3D, root-aligned, 20-50 mm
    auc_2d = pck_auc(errors_px, 0.0, 30.0, mask_2d)            # MPII+NZSL: 2D, 0-30 px

PCK follows Zimmermann and Brox's ``EvalUtil`` (used by the hand papers FrankMocap compares with): a joint is
correct when its error is <= the threshold; PCK is computed per joint over the examples where it is labelled, then
averaged over the joints labelled at least once; the curve has ``steps`` thresholds ``linspace(lo, hi, steps)``
(20 by default) and the AUC is its trapezoidal integral divided by ``hi - lo``, so 1 is perfect.
"""

import numpy as np
from jaxtyping import Bool, Float

AUC_STEPS = 20


def root_align(joints: Float[np.ndarray, "N J D"], root: int = 0) -> Float[np.ndarray, "N J D"]:
    """Joints relative to joint ``root`` of each example."""
    joints = np.asarray(joints, np.float64)
    if joints.ndim != 3:
        raise ValueError(f"joints: expected (N, J, D), got shape {joints.shape}")
    return joints - joints[:, root:root + 1]


def joint_errors(pred: Float[np.ndarray, "N J D"], gt: Float[np.ndarray, "N J D"]) -> Float[np.ndarray, "N J"]:
    """Euclidean distance of every joint."""
    pred, gt = _pair(pred, gt)
    return np.linalg.norm(pred - gt, axis=-1)


def mpjpe(pred: Float[np.ndarray, "N J D"], gt: Float[np.ndarray, "N J D"],
          mask: Bool[np.ndarray, "N J"]) -> Float[np.ndarray, "N"]:
    """Mean per-joint position error of each example over its labelled joints (NaN where none is)."""
    pred, gt = _pair(pred, gt)
    return _masked_mean(np.linalg.norm(pred - gt, axis=-1), _mask(mask, pred.shape[:2]))


def pa_mpjpe(pred: Float[np.ndarray, "N J 3"], gt: Float[np.ndarray, "N J 3"],
             mask: Bool[np.ndarray, "N J"]) -> Float[np.ndarray, "N"]:
    """MPJPE after the similarity transform (scale, rotation, translation) that best aligns each prediction to
    its ground truth over the labelled joints (Umeyama; NaN where no joint is labelled)."""
    pred, gt = _pair(pred, gt)
    mask = _mask(mask, pred.shape[:2])
    aligned = np.stack([procrustes_align(p, g, m) for p, g, m in zip(pred, gt, mask)]) if len(pred) else pred
    return mpjpe(aligned, gt, mask)


def procrustes_align(pred: Float[np.ndarray, "J 3"], gt: Float[np.ndarray, "J 3"],
                     mask: Bool[np.ndarray, "J"]) -> Float[np.ndarray, "J 3"]:
    """``s R pred + t`` minimising the squared error to ``gt`` over the joints in ``mask`` (all joints moved)."""
    if not mask.any():
        return pred
    p, g = pred[mask], gt[mask]
    mu_p, mu_g = p.mean(axis=0), g.mean(axis=0)
    x, y = p - mu_p, g - mu_g
    u, sigma, vt = np.linalg.svd(x.T @ y)
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    rotation = (u * [1.0, 1.0, d]) @ vt  # row-vector convention: aligned = x @ rotation
    var = np.sum(x * x)
    scale = (sigma[0] + sigma[1] + d * sigma[2]) / var if var > 0 else 1.0
    return scale * (pred - mu_p) @ rotation + mu_g


def pck(errors: Float[np.ndarray, "N J"], threshold: float, mask: Bool[np.ndarray, "N J"]) -> float:
    """Fraction of labelled joints with error <= ``threshold``, per joint then averaged over joints (NaN if no
    joint is labelled anywhere)."""
    return float(pck_curve(errors, np.array([threshold], np.float64), mask)[0])


def pck_curve(errors: Float[np.ndarray, "N J"], thresholds: Float[np.ndarray, "T"],
              mask: Bool[np.ndarray, "N J"]) -> Float[np.ndarray, "T"]:
    """`pck` at each threshold."""
    errors = np.asarray(errors, np.float64)
    if errors.ndim != 2:
        raise ValueError(f"errors: expected (N, J), got shape {errors.shape}")
    mask = _mask(mask, errors.shape)
    thresholds = np.asarray(thresholds, np.float64).reshape(-1)
    counts = mask.sum(axis=0)
    labelled = counts > 0
    if not labelled.any():
        return np.full(len(thresholds), np.nan)
    correct = (errors[None] <= thresholds[:, None, None]) & mask[None]  # T, N, J
    per_joint = correct.sum(axis=1)[:, labelled] / counts[labelled]
    return per_joint.mean(axis=1)


def pck_auc(errors: Float[np.ndarray, "N J"], lo: float, hi: float, mask: Bool[np.ndarray, "N J"],
            steps: int = AUC_STEPS) -> float:
    """Area under the PCK curve on ``linspace(lo, hi, steps)``, normalised to [0, 1] (NaN if nothing labelled)."""
    if not hi > lo or steps < 2:
        raise ValueError(f"lo, hi, steps: expected lo < hi and steps >= 2, got {lo}, {hi}, {steps}")
    thresholds = np.linspace(lo, hi, steps)
    curve = pck_curve(errors, thresholds, mask)
    return float(np.sum((curve[1:] + curve[:-1]) * np.diff(thresholds)) / 2 / (hi - lo))


def _pair(pred, gt):
    pred, gt = np.asarray(pred, np.float64), np.asarray(gt, np.float64)
    if pred.ndim != 3 or pred.shape != gt.shape:
        raise ValueError(f"pred, gt: expected two (N, J, D) arrays of one shape, got {pred.shape} and {gt.shape}")
    return pred, gt


def _mask(mask, shape) -> np.ndarray:
    mask = np.asarray(mask, bool)
    if mask.shape != tuple(shape):
        raise ValueError(f"mask: expected shape {tuple(shape)}, got {mask.shape}")
    return mask


def _masked_mean(values, mask):
    counts = mask.sum(axis=1)
    total = np.where(mask, values, 0.0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, total / np.maximum(counts, 1), np.nan)
