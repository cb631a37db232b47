"""``jaxmocap batch`` on Ray: bad inputs fail alone, a killed worker's video is retried to the same result, a
cluster is joined at its address, Ctrl-C stops a batch on its own Ray and SIGTERM one on a cluster cleanly (the
cluster left running; a task that lost its first cancel is cancelled again), outputs equal separate runs, a second
call rewrites nothing; and the run and live modes import one way.

Every batch runs the CLI in a process of its own (as a user would; Ray's state stays out of pytest's), on frames
20-28 of the bundled clip in chunks of 4 (tests/test_pipeline.py's shapes: the suite compiles them once, in its
shared compile cache), without overlay. Each Ray lives in a temporary folder of the test's and ends with it.
"""

import ast
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil
import pytest

from conftest import cli_as_from_a_terminal, temporary_files
from jaxmocap.batch import BatchConfig
from jaxmocap.batch.ledger import STOPPED
from jaxmocap.batch.videos import folder_names, read_manifest
from jaxmocap.cli import main
from jaxmocap.errors import InputError
from jaxmocap.pipeline import RunConfig

ROOT = Path(__file__).parents[1]
CLIP = ROOT / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"
OPTIONS = ["--start", "20", "--end", "28", "--chunk", "4", "--no-overlay", "--quiet"]
LOOPBACK = ("127.0.0.1", "::1", "::ffff:127.0.0.1")


def jaxmocap(*args: str) -> list[str]:
    return [sys.executable, "-m", "jaxmocap.cli", *args]


def ledger(out: Path) -> list[dict]:
    return json.loads((out / "batch.json").read_text())["videos"]


def assert_motions_equal(path: Path, reference: Path) -> None:
    ours, theirs = np.load(path), np.load(reference)
    assert sorted(ours.files) == sorted(theirs.files)
    for key in theirs.files:
        if theirs[key].dtype.kind in "fiub":
            np.testing.assert_allclose(ours[key], theirs[key], atol=1e-5, rtol=0, err_msg=key)
        else:
            assert ours[key] == theirs[key], key


def files_with_times(folder: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(folder)): (p.stat().st_mtime_ns, p.stat().st_size) for p in folder.rglob("*")}


def wait_for(predicate, seconds: float, what: str):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        found = predicate()
        if found:
            return found
        time.sleep(0.02)
    raise AssertionError(f"timed out after {seconds} s waiting for {what}")


def processes_in(folder: Path) -> list[psutil.Process]:
    """Ray's processes that live in ``folder`` (their command lines name it)."""
    found = []
    for proc in psutil.process_iter(["cmdline"]):
        if any(str(folder) in arg for arg in proc.info["cmdline"] or ()):
            found.append(proc)
    return found


def task_process(descending_from: int | None = None) -> psutil.Process | None:
    """The Ray worker running a video (Ray titles it ``ray::run_video``), below ``descending_from`` if given."""
    for proc in psutil.process_iter(["cmdline"]):
        if (proc.info["cmdline"] or [""])[0].startswith("ray::run_video"):
            if descending_from is None or descending_from in (p.pid for p in proc.parents()):
                return proc
    return None


@pytest.fixture(scope="module")
def ray_env():
    """The environment of the batches: Ray's files in a short temporary folder (its sockets' paths must stay
    short), removed after; no token file in the home folder."""
    folder = Path(tempfile.mkdtemp(prefix="ray-", dir="/tmp"))
    yield os.environ | {"RAY_TMPDIR": str(folder), "RAY_AUTH_MODE": "disabled"}, folder
    shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="module")
def clips(tmp_path_factory) -> dict[str, Path]:
    """The clip; an empty file of the same name (another folder); a corrupt one (the clip cut short)."""
    root = tmp_path_factory.mktemp("clips")
    (root / "good").mkdir()
    (root / "empty").mkdir()
    shutil.copy(CLIP, root / "good" / CLIP.name)
    (root / "empty" / CLIP.name).write_bytes(b"")
    (root / "corrupt.mp4").write_bytes(CLIP.read_bytes()[:3000])
    return {"good": root / "good" / CLIP.name, "empty": root / "empty" / CLIP.name, "corrupt": root / "corrupt.mp4"}


@pytest.fixture(scope="module")
def separate_run(tmp_path_factory) -> Path:
    """``jaxmocap run`` of the clip on its own: the motion every batch of it must equal."""
    out = tmp_path_factory.mktemp("separate")
    assert main(["run", str(CLIP), "--out", str(out), *OPTIONS]) == 0
    return out / "motion.npz"


@pytest.fixture(scope="module")
def local_batch(clips, ray_env, separate_run, tmp_path_factory):
    """A batch on a local Ray of two workers: the good clip, the empty file and the corrupt one (after the separate
    run, whose programs the workers read back from the compile cache instead of both compiling them at once)."""
    out = tmp_path_factory.mktemp("local") / "out"
    env, _ = ray_env
    proc = subprocess.run(jaxmocap("batch", str(clips["good"]), str(clips["empty"]), str(clips["corrupt"]),
                                   "--out", str(out), "--workers", "2", *OPTIONS),
                          capture_output=True, text=True, env=env, timeout=540)
    return proc, out


def test_bad_inputs_fail_alone_with_one_line_causes(local_batch, clips):
    proc, out = local_batch
    assert proc.returncode == 1, proc.stderr
    assert "1 of 3 videos done" in proc.stdout and "2 failed" in proc.stdout
    good, empty, corrupt = ledger(out)
    assert (good["input"], good["status"], good["error"]) == (str(clips["good"]), "done", None)
    # the people: the subject and the bystander at the back wall
    assert good["frames"] == 8 and good["valid"] == 8 and good["people"] == 2 and good["reprojection_px"] < 25
    for record, path in ((empty, clips["empty"]), (corrupt, clips["corrupt"])):
        assert record["status"] == "failed" and str(path) in record["error"] and "\n" not in record["error"]
        assert record["frames"] is None and record["seconds"] >= 0
    # two inputs with one stem, two folders
    assert (good["out"], empty["out"]) == (str(out / CLIP.stem), str(out / f"{CLIP.stem}_2"))
    rows = (out / "batch.csv").read_text().splitlines()
    assert rows[0] == "input,out,status,error,frames,people,valid,reprojection_px,seconds"
    assert [r.split(",")[2] for r in rows[1:]] == ["done", "failed", "failed"]


def test_batch_writes_what_run_writes(local_batch, separate_run):
    _, out = local_batch
    assert_motions_equal(out / CLIP.stem / "motion.npz", separate_run)
    ours = sorted(str(p.relative_to(out / CLIP.stem)) for p in (out / CLIP.stem).rglob("*"))
    theirs = sorted(str(p.relative_to(separate_run.parent)) for p in separate_run.parent.rglob("*"))
    assert ours == theirs


@pytest.fixture(scope="module")
def ray_head(ray_env):
    """A Ray head of two CPUs that the test starts in its temporary folder, on 127.0.0.1, and stops after (SIGTERM
    to ``ray start --block`` ends its processes): ``(address, pid)``."""
    env, folder = ray_env
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = env | {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0", "RAY_USAGE_STATS_ENABLED": "0"}
    head_dir = folder / "head"
    head = subprocess.Popen([str(Path(sys.executable).parent / "ray"), "start", "--head", "--block",
                             f"--port={port}", "--num-cpus=2", f"--temp-dir={head_dir}", "--include-dashboard=false",
                             "--disable-usage-stats", "--node-ip-address=127.0.0.1"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_for(lambda: (head_dir / "session_latest" / "logs" / "raylet.out").exists(), 120, "the Ray head")
        yield f"127.0.0.1:{port}", head.pid
    finally:
        head.send_signal(signal.SIGTERM)
        head.wait(timeout=60)
    wait_for(lambda: not processes_in(head_dir), 30, "the head's processes to end")


@pytest.fixture(scope="module")
def cluster_batch(ray_head, ray_env, tmp_path_factory):
    """A batch of the clip on the test's Ray head (``--address``) whose worker is killed (SIGKILL) mid-video, after
    its first chunk is stored: ``(process, out, killed worker, seconds)``."""
    address, head_pid = ray_head
    env, _ = ray_env
    out = tmp_path_factory.mktemp("cluster") / "out"
    started = time.perf_counter()
    batch = subprocess.Popen(jaxmocap("batch", str(CLIP), "--out", str(out), "--address", address, *OPTIONS),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    chunks = out / CLIP.stem / ".jaxmocap_chunks"
    try:
        wait_for(lambda: (chunks / "chunk_000000.npz").exists(), 420, "the first chunk")
        worker = task_process(descending_from=head_pid)
        assert worker is not None, "the video runs on the head's workers"
        assert not (out / CLIP.stem / "motion.npz").exists()  # mid-video
        worker.kill()
        stdout, stderr = batch.communicate(timeout=420)
    finally:
        batch.kill()
    return subprocess.CompletedProcess(batch.args, batch.returncode, stdout, stderr), out, worker, \
        time.perf_counter() - started


def test_batch_joins_a_cluster_at_its_address(cluster_batch, ray_head):
    proc, out, worker, _ = cluster_batch
    assert proc.returncode == 0, proc.stderr
    assert [v["status"] for v in ledger(out)] == ["done"]
    assert worker.pid not in (p.pid for p in psutil.process_iter())


def test_killed_worker_is_retried_to_the_same_result(cluster_batch, separate_run):
    proc, out, _, _ = cluster_batch
    assert proc.returncode == 0, proc.stderr
    assert_motions_equal(out / CLIP.stem / "motion.npz", separate_run)
    assert not (out / CLIP.stem / ".jaxmocap_chunks").exists() and not temporary_files(out)


def test_second_call_skips_finished_videos_and_rewrites_nothing(cluster_batch, ray_head, ray_env):
    first, out, _, first_seconds = cluster_batch
    assert first.returncode == 0, first.stderr
    before = files_with_times(out)
    started = time.perf_counter()
    proc = subprocess.run(jaxmocap("batch", str(CLIP), "--out", str(out), "--address", ray_head[0], *OPTIONS),
                          capture_output=True, text=True, env=ray_env[0], timeout=120)
    seconds = time.perf_counter() - started
    assert proc.returncode == 0, proc.stderr
    assert "1 finished before" in proc.stdout
    assert files_with_times(out) == before
    assert seconds < 0.25 * first_seconds, (seconds, first_seconds)


def test_a_second_call_keeps_the_first_calls_failures(local_batch, clips, ray_env):
    """The ledger is the folder's: a second call on the finished video alone leaves the empty and the corrupt file
    listed as failed (each video keeps its last status and error until it is run again) and rewrites nothing."""
    _, out = local_batch
    before = files_with_times(out)
    proc = subprocess.run(jaxmocap("batch", str(clips["good"]), "--out", str(out), *OPTIONS), capture_output=True,
                          text=True, env=ray_env[0], timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert [(row["input"], row["status"]) for row in ledger(out)] == [
        (str(clips["good"]), "done"), (str(clips["empty"]), "failed"), (str(clips["corrupt"]), "failed")]
    assert files_with_times(out) == before


def stopped_mid_video(out: Path, env: dict, stop: int, *args: str, while_running=lambda batch: None):
    """``jaxmocap batch CLIP ARGS`` on frames 20-100 (twenty chunks of the same shapes, so that the video is still
    running when the signal comes: with frames 20-60, a suite run on three workers once saw the video finish first),
    sent ``stop`` once its video has started and ``while_running(batch process)`` has looked: ``(exit code,
    stderr, what while_running returned)``. Started as from a terminal (`conftest.cli_as_from_a_terminal`): in a
    suite run as a background job the batch otherwise ignored SIGINT and finished the video (exit 0)."""
    options = [*OPTIONS[:3], "100", *OPTIONS[4:]]
    batch = subprocess.Popen(cli_as_from_a_terminal("batch", str(CLIP), "--out", str(out), *args, *options),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        wait_for(lambda: (out / CLIP.stem / ".jaxmocap_chunks" / "settings.json").exists(), 300, "the video to start")
        seen = while_running(batch)
        batch.send_signal(stop)
        _, stderr = batch.communicate(timeout=180)
    finally:
        batch.kill()
    return batch.returncode, stderr, seen


def assert_stopped_cleanly(out: Path, code: int, stderr: str, expected_code: int, note: str) -> None:
    """The exit code and one-line note, the video listed as stopped in batch.json, its stored chunks kept for the
    next call, nothing half-written."""
    assert code == expected_code, stderr
    assert stderr.strip().splitlines()[-1] == f"jaxmocap batch: {note}; run the same command again to resume"
    assert "Traceback" not in stderr
    assert not temporary_files(out) and not (out / CLIP.stem / "motion.npz").exists()
    assert (out / CLIP.stem / ".jaxmocap_chunks" / "settings.json").exists()
    (row,) = ledger(out)
    assert (row["status"], row["error"], row["frames"]) == ("stopped", STOPPED, None), row


def test_ctrl_c_stops_a_batch_on_its_own_ray_cleanly(ray_env, tmp_path):
    """SIGINT (Ctrl-C) mid-video: exit 130 with a one-line note, the video stopped (`assert_stopped_cleanly`), and
    the batch's own Ray, which listened on 127.0.0.1 alone, gone."""
    def listening_on_loopback(batch):
        ray_processes = psutil.Process(batch.pid).children(recursive=True)
        listening = [c.laddr.ip for p in ray_processes for c in p.net_connections("inet") if c.status == "LISTEN"]
        assert listening and set(listening) <= set(LOOPBACK), listening
        return ray_processes

    code, stderr, ray_processes = stopped_mid_video(tmp_path / "out", ray_env[0], signal.SIGINT, "--workers", "1",
                                                    while_running=listening_on_loopback)
    assert_stopped_cleanly(tmp_path / "out", code, stderr, 130, "interrupted")
    wait_for(lambda: not any(p.is_running() and p.status() != psutil.STATUS_ZOMBIE for p in ray_processes), 30,
             "the local Ray to stop")


def test_sigterm_stops_a_batch_on_a_cluster_and_leaves_the_cluster_running(ray_head, ray_env, tmp_path):
    """SIGTERM (``kill``, a job scheduler; Ray's own handler would end the batch at once) to a batch joined to a
    cluster (``--address``) mid-video: exit 143 with a one-line note, the video stopped (`assert_stopped_cleanly`),
    its task on the cluster's worker cancelled, and the cluster still running for its other users."""
    address, head_pid = ray_head
    head_dir = ray_env[1] / "head"
    servers = [p for p in processes_in(head_dir) if p.name() in ("gcs_server", "raylet")]
    code, stderr, _ = stopped_mid_video(
        tmp_path / "out", ray_env[0], signal.SIGTERM, "--address", address,
        while_running=lambda batch: wait_for(lambda: task_process(descending_from=head_pid), 60, "the task"))
    assert_stopped_cleanly(tmp_path / "out", code, stderr, 143, "terminated")
    wait_for(lambda: task_process(descending_from=head_pid) is None, 60, "the cancelled task to end")
    assert len(servers) == 2
    assert all(p.is_running() and p.status() != psutil.STATUS_ZOMBIE for p in [psutil.Process(head_pid), *servers])


STUBBORN = """
import sys, time
from pathlib import Path
from jaxmocap.batch.cluster import connect
from jaxmocap.batch.schedule import CANCEL_EVERY, stop
from jaxmocap.signals import cancellable

ray = connect(sys.argv[1], None)
running = Path(sys.argv[2])

@ray.remote(max_retries=0)
def stubborn():
    with cancellable():  # as `task.run_video`
        running.touch()
        lost = False  # the first Ctrl-C is lost, as in a library that catches it
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            try:
                time.sleep(0.01)
            except KeyboardInterrupt:
                if lost:
                    raise
                lost = True
    return "ran to its end"

ref = stubborn.remote()
while not running.exists():
    time.sleep(0.01)
started = time.monotonic()
assert stop(ray, [ref]) == []  # no result: cancelled
assert time.monotonic() - started < 3 * CANCEL_EVERY
"""


def test_a_task_that_loses_its_first_cancel_is_cancelled_again(ray_head, ray_env, tmp_path):
    """`schedule.stop` sends the cancel again while a task runs: a Ctrl-C lost in the task (its handler ran inside
    a library that caught it) does not let the video run to its end."""
    proc = subprocess.run([sys.executable, "-c", STUBBORN, ray_head[0], str(tmp_path / "running")],
                          capture_output=True, text=True, env=ray_env[0], timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]


def test_batch_without_ray_says_how_to_install_it(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray fails, as where the extra is not installed
    for name in ("RAY_USAGE_STATS_ENABLED", "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"):
        monkeypatch.setenv(name, "0")
    assert main(["batch", str(CLIP), "--out", str(tmp_path), *OPTIONS]) == 2
    assert capsys.readouterr().err == 'jaxmocap batch: error: batch needs Ray, an optional extra: pip install ' \
                                      '"jaxmocap[batch]"\n'


def test_inputs_get_distinct_folders_and_manifests_skip_comments(tmp_path):
    assert folder_names(["/a/clip.mp4", "/b/clip.mp4", "/c/clip_2.mp4", "/d/frames", "rtsp://cam:554/live/s1",
                         "/e/batch.json.mp4"]) == ["clip", "clip_2", "clip_2_2", "frames", "s1", "batch.json_2"]
    manifest = tmp_path / "videos.txt"
    manifest.write_text("# session 1\n/a/x.mp4\n\n  /b/y.mp4  \n")
    assert read_manifest(manifest) == ["/a/x.mp4", "/b/y.mp4"]
    with pytest.raises(InputError, match="--manifest: cannot read"):
        read_manifest(tmp_path / "missing.txt")
    with pytest.raises(InputError, match="--workers must be positive"):
        BatchConfig(("a.mp4",), RunConfig(""), workers=0)


def imports_of(path: Path, package: str) -> set[str]:
    """The modules of ``package`` that a source file imports, anywhere in it (in functions too)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith(package):
            found |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith(package)}
    return found


def in_a_cycle(graph: dict[str, set[str]], start: str) -> bool:
    seen, todo = set(), list(graph[start])
    while todo:
        module = todo.pop()
        if module == start:
            return True
        if module not in seen:
            seen.add(module)
            todo += graph[module]
    return False


def test_no_import_cycle_among_the_modes():
    """The run modes (`pipeline.entry` over `job` and `hands_job`), the live sessions (`live.entry` over `session`
    and `hands`) and the batch import one way: no module of theirs imports itself through others."""
    files = {".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): p
             for p in (ROOT / "jaxmocap").rglob("*.py")}
    graph = {m: {i for i in imports_of(p, "jaxmocap") if i in files and i != m} for m, p in files.items()}
    assert "jaxmocap.pipeline.job" in graph["jaxmocap.pipeline.entry"]  # the graph sees the imports
    scope = [m for m in graph if m.startswith(("jaxmocap.pipeline.", "jaxmocap.live.", "jaxmocap.batch."))]
    assert not [m for m in scope if in_a_cycle(graph, m)]
