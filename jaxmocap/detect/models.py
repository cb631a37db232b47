"""The BlazePose, hand and hand-recrop ``.tflite`` files: fetch from the official wheel, verify, cache, load.

The files are Apache-2.0 and ship inside the official ``mediapipe==0.10.21`` wheel (the last release that bundles
them). We download that wheel with pip (no install), extract the members, check their sha256 and cache them under
``$JAXMOCAP_CACHE/mediapipe-0.10.21/`` (default ``~/.cache/jaxmocap``). ``$JAXMOCAP_MEDIAPIPE_DIR`` (or the
``model_dir`` argument) points at an existing folder holding the five files instead.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from smplx_jax.default_model import cache_root
from smplx_jax.model_file import ModelFileError

from ..io import atomic_path, file_sha256

MEDIAPIPE_VERSION = "0.10.21"

# file name -> (member path inside the wheel, sha256)
MODEL_FILES: dict[str, tuple[str, str]] = {
    "pose_detection.tflite": (
        "mediapipe/modules/pose_detection/pose_detection.tflite",
        "9ba9dd3d42efaaba86b4ff0122b06f29c4122e756b329d89dca1e297fd8f866c",
    ),
    "pose_landmark_full.tflite": (
        "mediapipe/modules/pose_landmark/pose_landmark_full.tflite",
        "e9a5c5cb17f736fafd4c2ec1da3b3d331d6edbe8a0d32395855aeb2cdfd64b9f",
    ),
    "palm_detection_full.tflite": (
        "mediapipe/modules/palm_detection/palm_detection_full.tflite",
        "1b14e9422c6ad006cde6581a46c8b90dd573c07ab7f3934b5589e7cea3f89a54",
    ),
    "hand_landmark_full.tflite": (
        "mediapipe/modules/hand_landmark/hand_landmark_full.tflite",
        "11c272b891e1a99ab034208e23937a8008388cf11ed2a9d776ed3d01d0ba00e3",
    ),
    "hand_recrop.tflite": (
        "mediapipe/modules/holistic_landmark/hand_recrop.tflite",
        "67d996ce96f9d36fe17d2693022c6da93168026ab2f028f9e2365398d8ac7d5d",
    ),
}


def cache_dir() -> Path:
    """Where downloaded model files live: ``$JAXMOCAP_CACHE/mediapipe-0.10.21`` or ``~/.cache/jaxmocap/...``."""
    return cache_root() / f"mediapipe-{MEDIAPIPE_VERSION}"


def _check(path: Path, name: str) -> Path:
    expected = MODEL_FILES[name][1]
    actual = file_sha256(path)
    if actual != expected:
        raise ModelFileError(
            f"model file {path} is corrupt (sha256 {actual[:12]}…, expected {expected[:12]}…); "
            f"delete it and run again to re-download it from mediapipe=={MEDIAPIPE_VERSION}"
        )
    return path


def _download_wheel(tmp: str) -> Path:
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--disable-pip-version-check", "-q",
           f"mediapipe=={MEDIAPIPE_VERSION}", "-d", tmp]
    attempts = (cmd, cmd + ["--only-binary=:all:", "--platform", "manylinux_2_28_x86_64", "--python-version", "3.11"])
    errors = []
    for attempt in attempts:
        proc = subprocess.run(attempt, capture_output=True, text=True)
        wheels = sorted(Path(tmp).glob("mediapipe-*.whl"))
        if proc.returncode == 0 and wheels:
            return wheels[0]
        errors.append((proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no wheel"])
    raise ModelFileError(
        f"cannot download mediapipe=={MEDIAPIPE_VERSION} to extract the detector models ({errors[-1][0]}); "
        f"connect to PyPI once, or set JAXMOCAP_MEDIAPIPE_DIR to a folder holding {', '.join(MODEL_FILES)}"
    )


def _fetch_into(target: Path) -> None:
    """Download the wheel once and atomically place every missing model file in ``target``."""
    target.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="jaxmocap-wheel-") as tmp:
        wheel = _download_wheel(tmp)
        with zipfile.ZipFile(wheel) as zf:
            for name, (member, _) in MODEL_FILES.items():
                dest = target / name
                if dest.exists():
                    continue
                with atomic_path(dest) as part:
                    part.write_bytes(zf.read(member))
                    _check(part, name)


def model_path(name: str, model_dir: str | os.PathLike | None = None) -> Path:
    """Path of one verified model file (``name`` a key of ``MODEL_FILES``), downloading on first use."""
    if name not in MODEL_FILES:
        raise ValueError(f"unknown model file {name!r}; expected one of {sorted(MODEL_FILES)}")
    given = model_dir or os.environ.get("JAXMOCAP_MEDIAPIPE_DIR")
    if given:
        path = Path(given) / name
        if not path.is_file():
            raise ModelFileError(f"{path} not found; the folder given by model_dir/JAXMOCAP_MEDIAPIPE_DIR "
                                 f"must hold {', '.join(MODEL_FILES)} from mediapipe=={MEDIAPIPE_VERSION}")
        return _check(path, name)
    path = cache_dir() / name
    if not path.is_file():
        _fetch_into(cache_dir())
    return _check(path, name)


def ensure_models(model_dir: str | os.PathLike | None = None) -> dict[str, Path]:
    """All verified model paths by file name."""
    return {name: model_path(name, model_dir) for name in MODEL_FILES}


def load_interpreter(path: Path, num_threads: int = 2):
    """A LiteRT interpreter with its tensors allocated."""
    from ai_edge_litert.interpreter import Interpreter

    interpreter = Interpreter(model_path=str(path), num_threads=num_threads)
    interpreter.allocate_tensors()
    return interpreter


class TFLiteModel:
    """One loaded model: ``model(x)`` runs it on one float32 NHWC batch and returns outputs ordered by name."""

    def __init__(self, path: Path, num_threads: int = 2):
        self._interpreter = load_interpreter(path, num_threads)
        self._input = self._interpreter.get_input_details()[0]["index"]
        outputs = sorted(self._interpreter.get_output_details(), key=lambda d: d["name"])
        self._outputs = [d["index"] for d in outputs]
        self.input_shape = tuple(self._interpreter.get_input_details()[0]["shape"])

    def __call__(self, x):
        self._interpreter.set_tensor(self._input, x)
        self._interpreter.invoke()
        return [self._interpreter.get_tensor(i) for i in self._outputs]
