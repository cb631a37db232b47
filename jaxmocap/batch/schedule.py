"""`batch`: the videos not finished before become Ray tasks (one until a video is done, so that the programs are
compiled once; then a few in flight at a time), gathered as they finish into the ledger; a task whose worker died
is retried by Ray (and resumes from its stored chunks); Ctrl-C cancels the tasks in flight (each rolls its writes
back), lists the videos left as stopped and stops Ray."""

import dataclasses
import time
from dataclasses import dataclass
from itertools import islice
from pathlib import Path

from jaxmocap.batch.cluster import connect
from jaxmocap.batch.config import BatchConfig
from jaxmocap.batch.ledger import STOPPED, VideoRecord, finished, mark_path, video_key, write_ledger
from jaxmocap.batch.task import run_video
from jaxmocap.batch.videos import folder_names, resolved
from jaxmocap.detect.models import available_landmarks
from jaxmocap.pipeline.config import RunConfig

STOP_SECONDS = 60.0  # how long cancelled tasks get to roll back before their workers are killed
CANCEL_EVERY = 1.0  # seconds between the cancels sent to a task still running


@dataclass(frozen=True)
class Video:
    """One video of a batch: its `RunConfig`, output folder, mark path and `ledger.video_key`."""

    config: RunConfig
    out: Path
    mark: Path
    key: dict


@dataclass(frozen=True)
class BatchReport:
    """What a batch did: each video's record (input order), how many were finished before (skipped), the wall
    time and the ledger's path."""

    videos: list[VideoRecord]
    skipped: int
    seconds: float
    ledger: Path

    @property
    def failed(self) -> int:
        return sum(r.status == "failed" for r in self.videos)

    def summary(self) -> str:
        done = len(self.videos) - self.failed
        frames = sum(r.frames or 0 for r in self.videos)
        return (f"batch: {done} of {len(self.videos)} videos done ({self.skipped} finished before), "
                f"{self.failed} failed, {frames} frames, in {self.seconds:.1f} s; {self.ledger}")


def videos_of(config: BatchConfig, out_dir: Path) -> list[Video]:
    """The batch's videos: each input once, in its own folder ``out_dir/<name>``."""
    sources = resolved(config.inputs)
    videos = []
    for source, name in zip(sources, folder_names(sources)):
        run_config = dataclasses.replace(config.run, source=source, progress=False)
        videos.append(Video(run_config, out_dir / name, mark_path(out_dir, name), video_key(run_config)))
    return videos


def batch(config: BatchConfig, out_dir) -> BatchReport:
    """Run each video of ``config`` as ``jaxmocap run INPUT --out out_dir/<name>`` would, as Ray tasks, and keep
    ``out_dir/batch.json`` (and ``.csv``) up to date as they finish. Videos finished before with the same options
    and inputs are skipped (no Ray is started if none is left)."""
    started = time.perf_counter()
    out_dir = Path(out_dir).resolve()  # as the workers find it
    out_dir.mkdir(parents=True, exist_ok=True)
    if config.run.mode != "hands":  # the landmark model every video runs: fetched once, or full (said once)
        config = dataclasses.replace(config, run=dataclasses.replace(
            config.run, landmarks=available_landmarks(config.run.landmarks)))
    videos = videos_of(config, out_dir)
    records = {i: r for i, v in enumerate(videos) if (r := finished(v.mark, v.key, v.config.mode)) is not None}
    skipped = len(records)
    write_ledger(out_dir, [records[i] for i in sorted(records)])
    todo = [i for i in range(len(videos)) if i not in records]
    if todo:
        solve(config, out_dir, videos, todo, records)
    return BatchReport([records[i] for i in sorted(records)], skipped, time.perf_counter() - started,
                       out_dir / "batch.json")


def solve(config: BatchConfig, out_dir: Path, videos: list[Video], todo: list[int],
          records: dict[int, VideoRecord]) -> None:
    """The ``todo`` videos as Ray tasks, at most ``workers`` in flight; each finished one recorded in ``records``
    and the ledger rewritten. Until one video is done (now or in an earlier call), one runs at a time: its worker
    compiles the programs and the others read them back from the compile cache, instead of each compiling them at
    once."""
    from tqdm import tqdm

    ray = connect(config.address, config.workers)
    task = ray.remote(run_video).options(num_cpus=1, max_retries=config.retries, retry_exceptions=False)
    in_flight = config.workers or (len(todo) if config.address else int(ray.cluster_resources().get("CPU", 1)))
    queue, pending = iter(todo), {}

    def submit():
        compiled = any(r.status == "done" for r in records.values())  # here, or before: the cache holds them
        for i in islice(queue, max((in_flight if compiled else 1) - len(pending), 0)):
            v = videos[i]
            pending[task.remote(v.config, str(v.out), str(v.mark), v.key)] = i, time.perf_counter()

    def gather(refs):
        for ref in refs:
            i, submitted = pending.pop(ref)
            records[i] = outcome(ray, ref, videos[i], submitted, config.retries)
        write_ledger(out_dir, [records[i] for i in sorted(records)])

    bar = tqdm(total=len(videos), initial=len(videos) - len(todo), unit="video", desc="batch",
               disable=not config.run.progress)
    try:
        submit()
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            gather(ready)
            bar.update(len(ready))
            submit()
    except KeyboardInterrupt:
        running = {i: submitted for i, submitted in pending.values()}
        gather(stop(ray, list(pending)))
        now = time.perf_counter()
        for i in set(todo) - set(records):  # listed as stopped: those that were running, and those not started
            records[i] = VideoRecord.failure(str(videos[i].config.source), str(videos[i].out), STOPPED,
                                             now - running.get(i, now), status="stopped")
        write_ledger(out_dir, [records[i] for i in sorted(records)])
        raise
    finally:
        bar.close()
        ray.shutdown()


def outcome(ray, ref, video: Video, submitted: float, retries: int) -> VideoRecord:
    """A finished task's record; a task Ray gave up on (its worker died on every try) as a failed one."""
    try:
        return ray.get(ref)
    except ray.exceptions.WorkerCrashedError:
        cause = f"its worker died on each of {retries + 1} tries (killed, or out of memory)"
    except ray.exceptions.RayError as err:
        lines = [line for line in str(err).splitlines() if line.strip()]
        cause = f"{type(err).__name__}: {lines[-1] if lines else err}"
    return VideoRecord.failure(str(video.config.source), str(video.out), cause, time.perf_counter() - submitted)


def stop(ray, refs: list) -> list:
    """Cancel the tasks ``refs`` (Ctrl-C in each: its atomic writes roll back, its stored chunks stay) and wait for
    them, `STOP_SECONDS` at most before killing their workers; the refs that finished with a result meanwhile. The
    cancel is sent again every `CANCEL_EVERY` seconds to the tasks still running: a task's Ctrl-C can be lost where
    it lands (a library that catches it; a C extension being imported turns it into an ImportError), and its video
    would then run to its end."""
    deadline, running, ended = time.monotonic() + STOP_SECONDS, list(refs), []
    while running and time.monotonic() < deadline:
        for ref in running:
            ray.cancel(ref)
        done, running = ray.wait(running, num_returns=len(running),
                                 timeout=max(min(CANCEL_EVERY, deadline - time.monotonic()), 0.0))
        ended += done
    for ref in running:
        ray.cancel(ref, force=True)
    return [ref for ref in ended if _has_result(ray, ref)]


def _has_result(ray, ref) -> bool:
    try:
        ray.get(ref, timeout=0)
        return True
    except (ray.exceptions.RayError, TimeoutError):
        return False
