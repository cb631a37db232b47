"""`RunConfig`: every option of a run, built by the ``jaxmocap run`` and ``jaxmocap demo`` commands alike."""

import dataclasses
import hashlib
from dataclasses import dataclass, field
from pathlib import Path

from jaxmocap.detect.models import LANDMARK_MODELS
from jaxmocap.errors import InputError

MODES = ("whole", "body", "hands")
INTEGRATIONS = ("optimize", "copy-paste", "eft")
HAND_BOXES = ("keypoints", "body")
CAMERAS = ("turns", "static")
EXPORT_FILES = {"bvh": "motion.bvh", "gltf": "motion.glb"}
AT_THE_END = {"chunks": False}  # field metadata: an option used only after the last chunk, so stored chunks stay


@dataclass(frozen=True)
class RunConfig:
    """``jaxmocap run SOURCE [options]`` as one value: ``run(RunConfig(source, ...), out_dir)``.

    ``source``: a video file, image folder, single image or webcam index. ``mode``: ``whole`` (body and hands),
    ``body`` (no hand model runs, hands flat: FrankMocap's body demo) or ``hands`` (hands alone, no body needed:
    ``hands.npz``). ``model``: an SMPL-X model file (default: the built-in one). ``weights``: FrankMocap's converted
    regressors (from ``convert-frankmocap``); without them the embedded default path (detector landmarks -> IK ->
    fit). ``integration``: ``optimize`` (the fit), or with ``weights`` ``copy-paste`` or ``eft`` (the body regressor
    fine-tuned per frame). ``hand_boxes``: hand crops from the detector's ``keypoints``, or (with ``weights``) from
    the ``body`` regressor's projected hands (FrankMocap's fast mode). ``keypoints``: a folder of OpenPose JSON of
    one person to fit to instead of the detector's 2D keypoints (then one person is tracked). ``max_people``: people
    tracked at most (each gets an identity and a motion; the main one, seen in most frames, is ``motion.npz``).
    ``max_hands``: hands tracked at most in ``hands`` mode. ``landmarks``: BlazePose's landmark model (heavy, full
    or lite;
    ``full`` where the one asked for cannot be fetched, `jaxmocap.detect.models.available_landmarks`).
    ``start``/``end``/``stride``: the frames used. ``chunk_size``: frames per resumable chunk. ``iterations``: fit
    iterations. ``focal_length``: the camera's, pixels (default: a phone's main camera). ``camera``: ``turns``, a
    video camera's turns measured from the background (`jaxmocap.detect.camera_turns`; a still camera's are none),
    or ``static``, a camera held still (not measured). ``smooth``: the clip
    fit's motion between frames (False: frames fitted as unrelated images; ``hands`` mode: each side's frames
    fitted as one, `integrate.hand_clip`; copy-and-paste and EFT give the regressors' bodies unsmoothed);
    ``overlay``, ``exports`` (of `EXPORT_FILES`), ``frankmocap_pkl``, ``save_frames`` (a video's frames as
    images): the outputs besides the motions.

    A stored chunk is reused only under the same options (`chunk_key`), except those marked `AT_THE_END`.
    """

    source: str | Path
    mode: str = "whole"
    model: Path | None = None
    weights: Path | None = None
    integration: str = "optimize"
    hand_boxes: str = "keypoints"
    keypoints: Path | None = None
    max_people: int = 4
    max_hands: int = 2
    landmarks: str = "heavy"
    start: int = 0
    end: int | None = None
    stride: int = 1
    chunk_size: int = 128
    iterations: int = 20
    focal_length: float | None = None
    camera: str = "turns"
    smooth: bool = field(default=True, metadata=AT_THE_END)
    overlay: bool = field(default=True, metadata=AT_THE_END)
    exports: tuple[str, ...] = field(default=(), metadata=AT_THE_END)
    frankmocap_pkl: bool = field(default=False, metadata=AT_THE_END)
    save_frames: bool = field(default=False, metadata=AT_THE_END)
    progress: bool = field(default=True, metadata=AT_THE_END)

    def __post_init__(self):
        if self.mode not in MODES:
            raise InputError(f"unknown mode {self.mode!r} ({', '.join(MODES)})")
        if self.integration not in INTEGRATIONS:
            raise InputError(f"unknown integration {self.integration!r} ({', '.join(INTEGRATIONS)})")
        if self.landmarks not in LANDMARK_MODELS:
            raise InputError(f"unknown landmark model {self.landmarks!r} ({', '.join(LANDMARK_MODELS)})")
        if self.camera not in CAMERAS:
            raise InputError(f"unknown camera {self.camera!r} ({' or '.join(CAMERAS)})")
        if self.hand_boxes not in HAND_BOXES:
            raise InputError(f"unknown hand boxes {self.hand_boxes!r} ({' or '.join(HAND_BOXES)})")
        if self.mode == "hands":
            for refused, option in ((self.keypoints is not None, "--keypoints"),
                                    (self.integration != "optimize", f"--integration {self.integration}"),
                                    (self.hand_boxes == "body", "--hand-boxes body")):
                if refused:
                    raise InputError(f"--mode hands does not take {option} (it has no body)")
        if self.mode == "body" and self.hand_boxes == "body":
            raise InputError("--mode body does not take --hand-boxes body (it has no hands)")
        if self.integration != "optimize" and self.weights is None:
            raise InputError(f"--integration {self.integration} needs --weights (the regressors); the default path "
                             f"optimizes")
        if self.hand_boxes == "body" and self.weights is None:
            raise InputError("--hand-boxes body needs --weights (the body regressor gives the hand boxes)")
        if self.focal_length is not None and not self.focal_length > 0:
            raise InputError(f"--focal-length must be positive, got {self.focal_length}")
        for name in ("chunk_size", "iterations", "stride", "max_people", "max_hands"):
            if getattr(self, name) < (0 if name == "iterations" else 1):
                raise InputError(f"{name.replace('_', '-')} must be positive, got {getattr(self, name)}")
        unknown = sorted(set(self.exports) - set(EXPORT_FILES))
        if unknown:
            raise InputError(f"unknown export format(s) {', '.join(unknown)} (known: {', '.join(EXPORT_FILES)})")
        object.__setattr__(self, "exports", tuple(self.exports))

    @property
    def webcam(self) -> bool:
        return str(self.source).isdigit()


def chunk_key(config: RunConfig, model_sha256: str) -> dict:
    """What a stored chunk depends on: every option but those marked `AT_THE_END`, with each input named by its
    place and content (the model by its hash; files and folders by their names, sizes and modification times)."""
    key = {f.name: getattr(config, f.name) for f in dataclasses.fields(config) if f.metadata != AT_THE_END}
    for name in ("source", "weights", "keypoints"):
        if key[name] is not None and not (name == "source" and config.webcam):
            key[name] = _fingerprint(key[name])
    return {k: str(v) if isinstance(v, Path) else v for k, v in key.items()} | {"model": model_sha256}


def _fingerprint(path) -> str:
    path = Path(path).resolve()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path] if path.exists() else []
    stats = hashlib.sha256()
    for f in files:
        stat = f.stat()
        stats.update(f"{f.relative_to(path) if path.is_dir() else f.name} {stat.st_size} {stat.st_mtime_ns}\n".encode())
    return f"{path} {stats.hexdigest()[:16]}"
