"""`RunReport`: what a run of any mode wrote, and how long its stages took."""

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class RunReport:
    """What a run wrote, and how long each stage took (seconds). ``--mode hands``: ``motion`` is hands.npz,
    ``valid`` counts frames with a hand and ``people`` the hands' identities."""

    motion: Path
    frames: int
    valid: int
    seconds: dict[str, float]
    written: list[Path]
    people: list[int]  # the identities with a motion in ``people/<id>/``
    landmarks: str | None = None  # the BlazePose landmark model the detector ran (None: no body detector)
    camera: str | None = None  # how the camera moved (a video through a pinhole camera), one line
