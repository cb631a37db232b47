"""Import FrankMocap's released PyTorch checkpoints (hand ``pose_shape_best.pth`` + ``mean_mano_params.pkl``,
body SPIN/HMR ``.pt``) into our weights format. torch is needed here only."""

import pickle
from pathlib import Path

import numpy as np

from jaxmocap.regressors import weights
from jaxmocap.regressors.body import BodyConfig
from jaxmocap.regressors.hand import HandConfig
from jaxmocap.regressors.weights import WeightsError
from smplx_jax import safe_pickle

_HAND_PREFIXES = (("main_encoder.fc1.", "fc1."), ("main_encoder.", "encoder."), ("feat_encoder.1.", "feat_encoder."),
                  ("regressor.0.", "regressor."))
_ENCODER = ("conv1.", "bn1.", "layer1.", "layer2.", "layer3.", "layer4.")
_BUFFERS = ("init_pose", "init_shape", "init_cam")


def convert_frankmocap(hand: Path, hand_mean: Path, body: Path, out_dir: Path) -> list[Path]:
    """Convert the three files and write ``out_dir``; returns the files written."""
    hand_state = _read_torch(hand, "--hand")
    if "model" in hand_state:
        raise WeightsError(f"--hand {hand}: this is a body (HMR) checkpoint with a 'model' entry, not "
                           "FrankMocap's hand pose_shape_best.pth")
    hand_arrays = {_hand_name(k): v for k, v in _ours(hand_state).items()}
    hand_arrays["mean_params"] = _hand_mean_params(hand_mean)
    body_ckpt = _read_torch(body, "--body")
    if not isinstance(body_ckpt.get("model"), dict):
        what = "the hand checkpoint" if any(k.startswith("main_encoder.") for k in body_ckpt) else "a checkpoint"
        raise WeightsError(f"--body {body}: {what} without a 'model' entry, not FrankMocap's body (SPIN/HMR) .pt")
    body_arrays = {_body_name(k): v for k, v in _ours(body_ckpt["model"]).items()}
    for name in _BUFFERS:
        if name in body_arrays:
            body_arrays[name] = body_arrays[name].reshape(-1)
    regressors = weights.Regressors(
        hand=weights.build("hand", HandConfig(), hand_arrays, f"--hand {hand}"),
        body=weights.build("body", BodyConfig(), body_arrays, f"--body {body}"))
    return weights.save(out_dir, regressors, dict(hand=Path(hand).name, body=Path(body).name))


def _read_torch(path: Path, option: str) -> dict:
    try:
        import torch
    except ImportError:
        raise WeightsError("convert-frankmocap needs PyTorch to read the checkpoints: pip install torch") from None
    if not Path(path).is_file():
        raise WeightsError(f"{option} {path}: no such file")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises many types for truncated/corrupt/foreign files
        raise WeightsError(f"{option} {path}: cannot read as a PyTorch checkpoint (truncated or corrupt?): "
                           f"{_one_line(err)}") from None
    if not isinstance(ckpt, dict):
        raise WeightsError(f"{option} {path}: expected a dict of tensors, got {type(ckpt).__name__}")
    return ckpt


def _ours(state_dict: dict) -> dict[str, np.ndarray]:
    """PyTorch names and layouts -> ours: conv OIHW -> HWIO ``kernel``, linear (out,in) -> (in,out) ``kernel``,
    BatchNorm weight/running_mean/running_var -> scale/mean/var; ``num_batches_tracked`` dropped."""
    out = {}
    for key, tensor in state_dict.items():
        if not hasattr(tensor, "detach"):
            raise WeightsError(f"checkpoint entry {key} is a {type(tensor).__name__}, not a tensor")
        module, _, leaf = key.rpartition(".")
        array = tensor.detach().cpu().float().numpy()
        if leaf == "num_batches_tracked":
            continue
        if leaf == "weight" and array.ndim == 4:
            leaf, array = "kernel", array.transpose(2, 3, 1, 0)
        elif leaf == "weight" and array.ndim == 2:
            leaf, array = "kernel", array.T
        elif leaf == "weight" and array.ndim == 1:
            leaf = "scale"
        leaf = {"running_mean": "mean", "running_var": "var"}.get(leaf, leaf)
        out[f"{module}.{leaf}" if module else leaf] = np.ascontiguousarray(array)
    return out


def _one_line(err: Exception) -> str:
    return " ".join(str(err).split())[:300] or type(err).__name__


def _hand_name(key: str) -> str:
    for old, new in _HAND_PREFIXES:
        if key.startswith(old):
            return new + key[len(old):]
    return key


def _body_name(key: str) -> str:
    return "encoder." + key if key.startswith(_ENCODER) else key


def _hand_mean_params(path: Path) -> np.ndarray:
    """cam [5, 0, 0] + wrist [0, 0, 0] + mean_pose[3:] + 10 zero betas (FrankMocap builds it so at load)."""
    try:
        with open(path, "rb") as f:
            data = safe_pickle.load(f)
        mean_pose = np.asarray(data["mean_pose"], np.float32).reshape(-1)
    except FileNotFoundError:
        raise WeightsError(f"--hand-mean {path}: no such file") from None
    except safe_pickle.RefusedPickle as err:
        raise WeightsError(f"--hand-mean {path} refers to {err.reference}, which FrankMocap's mean_mano_params.pkl "
                           "does not hold: refused before anything in it was run") from None
    except (OSError, EOFError, pickle.UnpicklingError, TypeError, KeyError, ValueError, IndexError) as err:
        raise WeightsError(f"--hand-mean {path}: not FrankMocap's mean_mano_params.pkl ({_one_line(err)})") from None
    if mean_pose.shape != (48,):
        raise WeightsError(f"--hand-mean {path}: mean_pose has {mean_pose.size} values, expected 48")
    return np.concatenate([[5.0, 0.0, 0.0, 0.0, 0.0, 0.0], mean_pose[3:], np.zeros(10)]).astype(np.float32)
