"""The BlazePose, hand and hand-recrop ``.tflite`` files: fetch from their official packages, verify, cache, load.

The files are Apache-2.0. Five ship inside the official ``mediapipe==0.10.21`` wheel (the last release that bundles
them; `MODEL_FILES`): we download that wheel with pip (no install), extract the members, check their sha256 and
cache them under ``$JAXMOCAP_CACHE/mediapipe-0.10.21/`` (default ``~/.cache/jaxmocap``). BlazePose's heavy and lite
landmark models are not in the wheel; they ship in the npm package ``@mediapipe/pose@0.5.1675469404``
(`NPM_FILES`): ``npm pack`` fetches its tarball into a temporary folder (nothing installed), and the two members
are checked and cached beside the others, in ``mediapipe-pose-0.5.1675469404/``. ``$JAXMOCAP_MEDIAPIPE_DIR`` (or
the ``model_dir`` argument) points at an existing folder holding the files instead (for the npm files, the cache
and the fetch are tried where the folder lacks them).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from pathlib import Path

from smplx_jax.atomic_files import atomic_path
from smplx_jax.default_model import cache_root, private_folder
from smplx_jax.model_file import ModelFileError

from ..result_files import file_sha256

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


NPM_PACKAGE = "@mediapipe/pose@0.5.1675469404"
# file name -> (member path inside the npm tarball: package/<name>, sha256)
NPM_FILES: dict[str, tuple[str, str]] = {name: (f"package/{name}", sha256) for name, sha256 in (
    ("pose_landmark_heavy.tflite", "59e42d71bcd44cbdbabc419f0ff76686595fd265419566bd4009ef703ea8e1fe"),
    ("pose_landmark_lite.tflite", "f17bfbecadb61c3be1baa8b8d851cc6619c870a87167b32848ad20db306b9d61"),
)}
# BlazePose's landmark models (the same inputs and outputs), by the name ``--landmarks`` takes
LANDMARK_MODELS = {"heavy": "pose_landmark_heavy.tflite", "full": "pose_landmark_full.tflite",
                   "lite": "pose_landmark_lite.tflite"}
NPM_SECONDS = 300  # a fetch still running after this long has failed (npm retries an unreachable registry)


class ModelFetchError(ModelFileError):
    """A model file is not on this machine and could not be downloaded."""


def cache_dir() -> Path:
    """Where the wheel's model files live: ``$JAXMOCAP_CACHE/mediapipe-0.10.21`` or ``~/.cache/jaxmocap/...``."""
    return cache_root() / f"mediapipe-{MEDIAPIPE_VERSION}"


def npm_cache_dir() -> Path:
    """Where the npm package's model files live, beside `cache_dir`."""
    return cache_root() / f"mediapipe-pose-{NPM_PACKAGE.rsplit('@', 1)[1]}"


def _check(path: Path, name: str) -> Path:
    expected = (MODEL_FILES | NPM_FILES)[name][1]
    actual = file_sha256(path)
    if actual != expected:
        origin = f"mediapipe=={MEDIAPIPE_VERSION}" if name in MODEL_FILES else NPM_PACKAGE
        raise ModelFileError(
            f"model file {path} is corrupt (sha256 {actual[:12]}…, expected {expected[:12]}…); "
            f"delete it and run again to re-download it from {origin}"
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
    raise ModelFetchError(
        f"cannot download mediapipe=={MEDIAPIPE_VERSION} to extract the detector models ({errors[-1][0]}); "
        f"connect to PyPI once, or set JAXMOCAP_MEDIAPIPE_DIR to a folder holding {', '.join(MODEL_FILES)}"
    )


def _fetch_into(target: Path) -> None:
    """Download the wheel once and atomically place every missing model file in ``target``."""
    private_folder(target)
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


def _npm_fetch_into(target: Path) -> None:
    """``npm pack`` the package into a temporary folder (its own npm cache there too) and atomically place every
    missing `NPM_FILES` member in ``target``; `ModelFetchError` when npm is missing or the fetch fails."""
    npm = shutil.which("npm")
    how = (f"to use them, put {' and '.join(NPM_FILES)} from `npm pack {NPM_PACKAGE}` in {target} or in "
           f"$JAXMOCAP_MEDIAPIPE_DIR")
    if npm is None:
        raise ModelFetchError(f"cannot fetch BlazePose heavy and lite (npm not found on PATH); {how}")
    private_folder(target)
    with tempfile.TemporaryDirectory(prefix="jaxmocap-npm-") as tmp:
        cmd = [npm, "pack", NPM_PACKAGE, "--pack-destination", tmp, "--cache", str(Path(tmp) / "cache"),
               "--ignore-scripts", "--silent"]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=NPM_SECONDS, stdin=subprocess.DEVNULL)
            failure = None if proc.returncode == 0 else ((proc.stderr or proc.stdout).strip().splitlines()
                                                         or ["no output"])[-1]
        except subprocess.TimeoutExpired:
            failure = f"no answer in {NPM_SECONDS} s"
        tarballs = sorted(Path(tmp).glob("*.tgz"))
        if failure or not tarballs:
            raise ModelFetchError(f"cannot fetch BlazePose heavy and lite with npm ({failure or 'no tarball'}); "
                                  f"{how}")
        with tarfile.open(tarballs[0]) as archive:
            for name, (member, _) in NPM_FILES.items():
                dest = target / name
                if dest.exists():
                    continue
                with atomic_path(dest) as part:
                    part.write_bytes(archive.extractfile(member).read())
                    _check(part, name)


def model_path(name: str, model_dir: str | os.PathLike | None = None) -> Path:
    """Path of one verified model file (``name`` a key of `MODEL_FILES` or `NPM_FILES`), downloading on first use.
    Raises `ModelFetchError` when it cannot be had, `ModelFileError` when a copy found is corrupt."""
    if name in NPM_FILES:
        return _npm_model_path(name, model_dir)
    if name not in MODEL_FILES:
        raise ValueError(f"unknown model file {name!r}; expected one of {sorted(MODEL_FILES | NPM_FILES)}")
    given = model_dir or os.environ.get("JAXMOCAP_MEDIAPIPE_DIR")
    if given:
        path = Path(given) / name
        if not path.is_file():
            raise ModelFetchError(f"{path} not found; the folder given by model_dir/JAXMOCAP_MEDIAPIPE_DIR "
                                 f"must hold {', '.join(MODEL_FILES)} from mediapipe=={MEDIAPIPE_VERSION}")
        return _check(path, name)
    path = cache_dir() / name
    if not path.is_file():
        _fetch_into(cache_dir())
    return _check(path, name)


def _npm_model_path(name: str, model_dir) -> Path:
    given = model_dir or os.environ.get("JAXMOCAP_MEDIAPIPE_DIR")
    if given and (Path(given) / name).is_file():
        return _check(Path(given) / name, name)
    path = npm_cache_dir() / name
    if not path.is_file():
        _npm_fetch_into(npm_cache_dir())
    return _check(path, name)


def ensure_models(model_dir: str | os.PathLike | None = None) -> dict[str, Path]:
    """The wheel's verified model paths (`MODEL_FILES`) by file name."""
    return {name: model_path(name, model_dir) for name in MODEL_FILES}


def landmark_model_path(landmarks: str, model_dir: str | os.PathLike | None = None) -> Path:
    """The verified file of BlazePose's ``landmarks`` model (a key of `LANDMARK_MODELS`)."""
    if landmarks not in LANDMARK_MODELS:
        raise ValueError(f"landmarks must be one of {', '.join(LANDMARK_MODELS)}, got {landmarks!r}")
    return model_path(LANDMARK_MODELS[landmarks], model_dir)


def available_landmarks(landmarks: str, model_dir: str | os.PathLike | None = None) -> str:
    """The landmark model a run asking for ``landmarks`` uses: that one, fetched on first use, or ``full`` (the
    wheel's) where its file cannot be had, said in one line on stderr. A corrupt copy is `ModelFileError`."""
    try:
        landmark_model_path(landmarks, model_dir)
    except ModelFetchError as err:
        if landmarks == "full":
            raise
        print(f"notice: {err}; running BlazePose full instead", file=sys.stderr, flush=True)
        return "full"
    return landmarks


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
