"""Evaluate hand regressors on hand benchmarks, a table like the paper's Table 2 (one row per weights folder).

    python -m train.evaluate --dataset stb,rhd,mpii_nzsl --data-dir DATA --weights runs/a/weights[,runs/b/weights]
                             [--split test] [--limit N] [--json results.json]

``--data-dir`` is one root per dataset (comma-separated, in the order of ``--dataset``), or, for several datasets,
one folder holding a folder named after each. Each sample is cut by the deterministic evaluation crop
(`train.augment.hand_example`, left hands mirrored to right) and predicted as a right hand. Columns, per dataset,
as its labels allow:

- ``auc_3d_20_50mm``, ``mpjpe_mm``, ``pa_mpjpe_mm``: 3D joints (hand_forward of the prediction) and labels both
  root-aligned at the wrist, millimetres; PCK AUC over 20-50 mm as for STB and RHD.
- ``auc_2d_0_30px``: 2D PCK AUC over 0-30 pixels of the original image, as for MPII+NZSL. The network's 2D joints
  are in crop coordinates; errors there are scaled by the crop's side in image pixels (half the side per crop
  unit), which `crops.hand_windows` gives for the sample's box (the region the evaluation crop resizes).
"""

import argparse
import functools
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import jax
import numpy as np
from flax import nnx
from jaxtyping import Array, Bool, Float

import smplx_jax
from jaxmocap.buckets import pad_rows
from jaxmocap.errors import InputError
from jaxmocap.regressors import crops
from jaxmocap.regressors.weights import load_network
from train.augment import hand_example
from train.datasets import HAND_DATASETS, HandSample, open_dataset
from train.losses import hand_crop_joints, right_hand_joints
from train.metrics import joint_errors, mpjpe, pa_mpjpe, pck_auc, root_align

BATCH_SIZE = 16
LABELS = {"auc_3d_20_50mm": "3D AUC 20-50mm", "auc_2d_0_30px": "2D AUC 0-30px", "mpjpe_mm": "MPJPE mm",
          "pa_mpjpe_mm": "PA-MPJPE mm"}


def hand_metrics(pred_3d: Float[np.ndarray, "N 21 3"], gt_3d: Float[np.ndarray, "N 21 3"],
                 mask_3d: Bool[np.ndarray, "N 21"], pred_2d: Float[np.ndarray, "N 21 2"],
                 gt_2d: Float[np.ndarray, "N 21 2"], mask_2d: Bool[np.ndarray, "N 21"]) -> dict[str, float]:
    """The metrics the labels allow: 3D ones (millimetres, root-aligned here at joint 0) where any 3D joint is
    labelled, the 2D AUC (pixels) where any 2D joint is."""
    metrics = {}
    if np.any(mask_3d):
        pred, gt = root_align(pred_3d), root_align(gt_3d)
        metrics["auc_3d_20_50mm"] = pck_auc(joint_errors(pred, gt), 20.0, 50.0, mask_3d)
        metrics["mpjpe_mm"] = float(np.nanmean(mpjpe(pred, gt, mask_3d)))
        metrics["pa_mpjpe_mm"] = float(np.nanmean(pa_mpjpe(pred, gt, mask_3d)))
    if np.any(mask_2d):
        metrics["auc_2d_0_30px"] = pck_auc(joint_errors(pred_2d, gt_2d), 0.0, 30.0, mask_2d)
    return metrics


@functools.partial(jax.jit, static_argnums=0)
def _raw(graphdef, state, images):
    return nnx.merge(graphdef, state)(images)


@jax.jit
def _joints(model, right_hand, raw: Float[Array, "N 61"]):
    joints = jax.vmap(right_hand_joints, in_axes=(None, None, 0))(model, right_hand, raw)
    return joints, jax.vmap(hand_crop_joints)(joints, raw[:, :3])


def evaluate_hands(network: nnx.Module, model: smplx_jax.BodyModel, right_hand: smplx_jax.HandModel,
                   samples: Sequence[HandSample], batch_size: int = BATCH_SIZE,
                   limit: int | None = None, image_size: int = crops.SIZE) -> dict[str, float]:
    """`hand_metrics` of ``network`` on ``samples`` (the first ``limit`` of them; every batch padded to
    ``batch_size``: one compilation), plus ``count``, the number of samples evaluated."""
    if batch_size < 1 or (limit is not None and limit < 0):
        raise ValueError(f"batch_size, limit: expected >= 1 and None or >= 0, got {batch_size}, {limit}")
    count = len(samples) if limit is None else min(limit, len(samples))
    graphdef, state = nnx.split(network)
    parts = []
    for start in range(0, count, batch_size):
        chunk = [samples[i] for i in range(start, min(start + batch_size, count))]
        examples = [hand_example(s, image_size) for s in chunk]
        images = pad_rows(np.stack([e.image for e in examples]).astype(np.float32), batch_size)
        joints, crop = (np.asarray(a)[:len(chunk)] for a in _joints(model, right_hand, _raw(graphdef, state, images)))
        sides = np.array([pixels_per_crop_unit(s) for s in chunk])[:, None, None]
        parts.append(dict(
            pred_3d=joints * 1000, gt_3d=np.stack([e.joints_3d for e in examples]) * 1000,
            mask_3d=np.repeat(np.stack([e.joints_3d_mask for e in examples])[:, None], 21, axis=1),
            pred_2d=crop * sides, gt_2d=np.stack([e.joints_2d for e in examples]) * sides,
            mask_2d=np.stack([e.joints_2d_mask for e in examples])))
    if not parts:
        return dict(count=0)
    stacked = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    return hand_metrics(**stacked) | dict(count=count)


def pixels_per_crop_unit(sample: HandSample) -> float:
    """Image pixels per unit of the evaluation crop's coordinates [-1, 1] (half the side of the square region
    `crops.hand_windows` cuts for the sample's box)."""
    window = crops.hand_windows(np.asarray(sample.box)[None], sample.image.shape[1::-1])
    return float(window.size[0, 0]) / 2


def format_table(results: dict[str, dict[str, dict[str, float]]]) -> str:
    """``results[weights][dataset][metric]`` as a text table: a row per weights, per dataset its metrics."""
    datasets = list(dict.fromkeys(d for row in results.values() for d in row))
    columns = [(d, m) for d in datasets for m in LABELS if any(m in row.get(d, {}) for row in results.values())]
    header = ["weights"] + [f"{d} {LABELS[m]}" for d, m in columns]
    rows = [[name] + [_cell(row.get(d, {}).get(m), m) for d, m in columns] for name, row in results.items()]
    widths = [max(len(r[i]) for r in [header] + rows) for i in range(len(header))]
    lines = ["  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(r, widths)))
             for r in [header] + rows]
    return "\n".join(lines[:1] + ["-" * len(lines[0])] + lines[1:])


def _cell(value, metric: str) -> str:
    if value is None:
        return "-"
    return f"{value:.3f}" if metric.startswith("auc") else f"{value:.1f}"


def _roots(datasets: list[str], data_dir: str) -> list[Path]:
    dirs = [Path(d) for d in data_dir.split(",")]
    if len(dirs) == len(datasets):
        return dirs
    if len(dirs) == 1:
        return [dirs[0] / name for name in datasets]
    raise ValueError(f"--data-dir: expected one folder or one per dataset ({len(datasets)}), got {len(dirs)}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(allow_abbrev=False, prog="python -m train.evaluate",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", required=True, help=f"comma-separated, of: {', '.join(HAND_DATASETS)}")
    parser.add_argument("--data-dir", required=True, help="one root per dataset, or one folder of dataset folders")
    parser.add_argument("--weights", required=True, help="comma-separated weights folders (a table row each)")
    parser.add_argument("--split", default="test")
    parser.add_argument("--limit", type=int, default=None, help="the first N samples of each dataset")
    parser.add_argument("--batch-size", type=int, default=BATCH_SIZE)
    parser.add_argument("--image-size", type=int, default=crops.SIZE,
                        help="crop side the network was trained at (default: %(default)s, FrankMocap's)")
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    args = parser.parse_args(argv)
    try:
        datasets = args.dataset.split(",")
        unknown = [d for d in datasets if d not in HAND_DATASETS]
        if unknown:
            raise ValueError(f"--dataset: {', '.join(unknown)} not hand datasets; known: {', '.join(HAND_DATASETS)}")
        roots = _roots(datasets, args.data_dir)
        model = smplx_jax.load_model(smplx_jax.default_model_path())
        right_hand = smplx_jax.hand_model(model, "right")
        opened = {name: open_dataset(name, root, args.split) for name, root in zip(datasets, roots)}
        results = {}
        for weights in args.weights.split(","):
            network = load_network(weights, "hand")
            results[weights] = {name: evaluate_hands(network, model, right_hand, samples, args.batch_size,
                                                     args.limit, args.image_size)
                                for name, samples in opened.items()}
    except (ValueError, OSError, InputError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(format_table(results))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(dict(split=args.split, limit=args.limit, results=results), indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
