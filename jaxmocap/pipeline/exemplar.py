"""``--integration eft``: the body regressor fine-tuned per frame on the detector's BODY_25 keypoints (EFT)."""

import jax
import jax.numpy as jnp
import numpy as np

import smplx_jax
from jaxmocap.buckets import pad_rows, padded_size
from jaxmocap.integrate.eft import EFTConfig, fine_tune
from jaxmocap.regressors import BodyOutput, Predictor, crops


def fine_tuned_bodies(predictor: Predictor, model: smplx_jax.BodyModel, images, frame, boxes, keypoints,
                      config: EFTConfig = EFTConfig()):
    """As `regressors.predict_bodies` (``images (F, H, W, 3)`` uint8 BGR, per body its ``frame`` and box ``(x, y,
    w, h)``, NaN rows missing), with each body fine-tuned on its ``keypoints (N, >=25, 3)`` (image pixels, OpenPose
    order, confidence; BODY_25 used). Returns ``(BodyOutput, window, valid)``, NaN where not ``valid``."""
    boxes = np.asarray(boxes, np.float64)
    present = np.all(np.isfinite(boxes), axis=-1)
    window = crops.body_windows(np.where(present[:, None], boxes, 0.0), images.shape[2:0:-1])
    valid = present & window.ok
    keep = np.flatnonzero(valid)
    n, m = len(valid), len(keep)
    if m == 0:
        return BodyOutput(*(jnp.full((n,) + shape, jnp.nan) for shape in ((24, 3, 3), (10,), (3,)))), window, valid
    rows = pad_rows(keep, padded_size(m, predictor.buckets))  # a bucket's rows reuse compiled functions
    sub = crops.Window(*(np.asarray(a)[rows] for a in window))
    frame = np.broadcast_to(np.asarray(frame, np.int32), (n,))[rows]
    batch = crops.normalize_body(crops.crop(images, frame, sub))
    body25 = np.asarray(keypoints, np.float32)[rows, :25]
    targets = np.concatenate([np.asarray(crops.image_to_crop(body25[..., :2], sub)), body25[..., 2:]], axis=-1)
    graphdef, state = predictor.body_network
    out = fine_tune(graphdef, state, batch, targets, model, config).output
    full = jax.tree.map(lambda a: jnp.full((n,) + a.shape[1:], jnp.nan, a.dtype).at[keep].set(a[:m]), out)
    return full, window, valid
