"""What became of each video: ``DIR/batch.json`` and ``DIR/batch.csv`` (docs/formats.md), rewritten atomically as
videos finish, and the marks of finished videos (``DIR/.jaxmocap_batch/<name>.json``: the options and inputs the
video's outputs were made from, and its record) that let a second call skip them."""

import csv
import dataclasses
import io
import json
from dataclasses import dataclass
from pathlib import Path

import smplx_jax
from jaxmocap.pipeline.config import AT_THE_END, RunConfig, chunk_key
from jaxmocap.result_files import file_sha256
from smplx_jax.atomic_files import atomic_write_text

MARKS = ".jaxmocap_batch"
STATUSES = ("done", "failed", "stopped")
STOPPED = "stopped (Ctrl-C or SIGTERM) before it finished; the same command resumes it"


@dataclass(frozen=True)
class VideoRecord:
    """One video of ``batch.json``: its ``input`` and output folder ``out``; ``status`` ``done``, ``failed`` or
    ``stopped`` (by Ctrl-C, running or not yet started); ``error``, the one-line cause of a failure or stop (else
    None); ``frames`` solved, ``people`` tracked (hands in ``--mode hands``), ``valid`` frames with someone,
    ``reprojection_px`` the median reprojection error of the main person's valid frames (None without any; all
    these None unless done); ``seconds`` of wall time."""

    input: str
    out: str
    status: str
    error: str | None
    frames: int | None
    people: int | None
    valid: int | None
    reprojection_px: float | None
    seconds: float

    def __post_init__(self):
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {self.status!r}")
        if (self.status == "done") != (self.error is None) or "\n" in (self.error or ""):
            raise ValueError(f"error: one line for a failed or stopped video, None for a done one; got {self.error!r}")

    @classmethod
    def failure(cls, source: str, out: str, cause: str, seconds: float, status: str = "failed") -> "VideoRecord":
        return cls(source, out, status, one_line(cause), None, None, None, None, round(seconds, 3))


FIELDS = tuple(f.name for f in dataclasses.fields(VideoRecord))


def one_line(cause: str) -> str:
    """A cause on one line: its lines joined, runs of white space as one space (never empty)."""
    return " ".join(str(cause).split()) or "unknown error"


def ledger_texts(records: list[VideoRecord]) -> dict[str, str]:
    """``batch.json`` and ``batch.csv`` of ``records`` (in that order), as text."""
    rows = [dataclasses.asdict(r) for r in records]
    table = io.StringIO()
    writer = csv.DictWriter(table, FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: "" if v is None else v for k, v in row.items()} for row in rows)
    return {"batch.json": json.dumps({"videos": rows}, indent=2) + "\n", "batch.csv": table.getvalue()}


def read_ledger(out_dir: Path) -> list[VideoRecord]:
    """The records of ``out_dir/batch.json`` (none where it is missing or unreadable)."""
    try:
        return [VideoRecord(**row) for row in json.loads((Path(out_dir) / "batch.json").read_text())["videos"]]
    except (OSError, ValueError, KeyError, TypeError):
        return []


def merged(earlier: list[VideoRecord], records: list[VideoRecord]) -> list[VideoRecord]:
    """``earlier`` records with each of ``records`` in place of the one of its output folder, the others after."""
    new = {r.out: r for r in records}
    kept = [new.pop(r.out, r) for r in earlier]
    return kept + [r for r in records if r.out in new]


def write_ledger(out_dir: Path, records: list[VideoRecord]) -> list[Path]:
    """``out_dir/batch.json`` and ``batch.csv`` of every video the folder has seen: what the ledger held, with
    ``records`` in place of their videos' earlier records (a video keeps its last status and error until it is
    run again), each file written atomically and only where its text changed; the paths written."""
    written = []
    for name, text in ledger_texts(merged(read_ledger(out_dir), records)).items():
        path = Path(out_dir) / name
        if not path.is_file() or path.read_text() != text:
            written.append(atomic_write_text(path, text))
    return written


def video_key(config: RunConfig) -> dict:
    """What a video's outputs depend on, as JSON values: every option of ``config`` but ``progress``, its inputs by
    place and content (`config.chunk_key`) and the body model by its hash."""
    model = smplx_jax.model_path(config.model)
    model_sha256 = file_sha256(model) if model.is_file() else f"missing {model}"
    at_the_end = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)
                  if f.metadata == AT_THE_END and f.name != "progress"}
    return json.loads(json.dumps(chunk_key(config, model_sha256) | at_the_end, default=str))


def main_output(out: Path, mode: str) -> Path:
    """The file a finished run of ``mode`` always writes in ``out``."""
    return Path(out) / ("hands.npz" if mode == "hands" else "motion.npz")


def mark_path(out_dir: Path, name: str) -> Path:
    """Where a batch keeps the mark of its video ``name`` (``<out>/.jaxmocap_batch/<name>.json``)."""
    return Path(out_dir) / MARKS / f"{name}.json"


def write_mark(path: Path, key: dict, record: VideoRecord) -> Path:
    """A video's mark (its settings ``key`` and its `VideoRecord`) written atomically to ``path``."""
    return atomic_write_text(path, json.dumps({"key": key, "record": dataclasses.asdict(record)}, indent=1))


def finished(path: Path, key: dict, mode: str) -> VideoRecord | None:
    """The record of a video finished before with the same ``key`` whose outputs are still there, else None."""
    try:
        mark = json.loads(Path(path).read_text())
        record = VideoRecord(**mark["record"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if mark.get("key") != key or record.status != "done" or not main_output(Path(record.out), mode).is_file():
        return None
    return record
