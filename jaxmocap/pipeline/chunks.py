"""Frames in chunks (`frame_batches`) and the resumable chunk store: each finished chunk of frames is a file; a rerun
with the same settings skips them."""

import io
import json
import shutil
from collections.abc import Callable, Iterator
from itertools import islice
from pathlib import Path

import numpy as np

from jaxmocap.pipeline.stage_clock import StageClock
from jaxmocap.pipeline.tracks import Chunk
from smplx_jax.atomic_files import atomic_write_bytes, atomic_write_text


class ChunkStore:
    """``<out>/.jaxmocap_chunks/``: ``settings.json`` and ``chunk_<k>.npz``, each a ``record`` (`Chunk`, or another
    class with ``arrays()`` and ``from_arrays``). Settings (`config.chunk_key`) that differ from the stored ones
    (another input, range, model or option) discard the stored chunks."""

    def __init__(self, out_dir: Path, settings: dict, record=Chunk):
        self.record = record
        self.folder = Path(out_dir) / ".jaxmocap_chunks"
        stored = self.folder / "settings.json"
        text = json.dumps(settings, sort_keys=True)
        if stored.is_file() and stored.read_text() != text:
            shutil.rmtree(self.folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        atomic_write_text(stored, text)

    def _path(self, index: int) -> Path:
        return self.folder / f"chunk_{index:06d}.npz"

    def load(self, index: int):
        path = self._path(index)
        if not path.is_file():
            return None
        with np.load(path, allow_pickle=False) as data:
            return self.record.from_arrays({k: data[k] for k in data.files})

    def save(self, index: int, chunk) -> None:
        buffer = io.BytesIO()
        np.savez(buffer, **chunk.arrays())
        atomic_write_bytes(self._path(index), buffer.getvalue())

    def clear(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)


def frame_batches(frames: Iterator, size: int, clock: StageClock) -> Iterator[tuple[int, list]]:
    """Lists of ``size`` items of ``frames`` (the last shorter), numbered from 0, their reading timed as ``decode``.
    A list is let go before the next is read (a chunk of decoded frames is the run's largest holding: 128 frames of
    1080p video are 800 MB), so the caller must let it go too, and not number them with `enumerate`, whose last
    pair lives on while the next item is read."""
    index = 0
    while True:
        with clock("decode"):
            batch = list(islice(frames, size))
        if not batch:
            return
        yield index, batch
        del batch
        index += 1


def stored_or_solved(frames: Iterator, size: int, store: ChunkStore, clock: StageClock, solve: Callable,
                     written: Callable, restore: Callable, bar) -> Iterator:
    """Each chunk of ``size`` frames of ``frames`` (`frame_batches`): the store's where it holds it (``restore(chunk)``
    carries the trackers on from it), else ``solve(ids, frames, previous)`` (``previous``: the chunk before, or
    None), its keypoints written (``written(chunk, first)``, ``first`` its first frame's number in the run) before
    it is stored. ``bar`` (tqdm) counts the frames."""
    done, previous = 0, None
    for index, batch in frame_batches(frames, size, clock):
        ids = np.asarray([i for i, _ in batch])
        chunk = store.load(index)
        if chunk is None or not np.array_equal(chunk.frame_index, ids):
            chunk = solve(ids, [frame for _, frame in batch], previous)
            with clock("keypoints"):  # before the chunk is stored: a stored chunk has its keypoints written
                written(chunk, done)
            store.save(index, chunk)
        else:
            restore(chunk)
        del batch  # its frames go before the next chunk's are read
        previous = chunk
        yield chunk
        done += len(ids)
        bar.update(len(ids))
        bar.set_postfix(fps=f"{done / max(clock.total, 1e-9):.1f}")
