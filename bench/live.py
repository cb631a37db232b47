"""Live capture (`jaxmocap live`): sustained frames/s, latency from a frame's arrival to its parameters out (median
and 95th percentile) and frames dropped, on the bundled clip played as if live at its own 60 frames/s; each
thread's CPU time per frame solved (`ThreadCpu`: where the cores go); and how far the causal result is from the
offline ``jaxmocap run`` on each shipped view (PA-MPJPE of the body joints).

    python bench/live.py [--out bench/results] [--quick]      (or: jaxmocap bench --only live)

Rows: the live path alone; with the web page watched (a viewer reading the MJPEG stream) and every frame sent as
a UDP JSON line. Each plays the clip ``LOOPS`` times (``--quick``: twice). Compilation happens before the first
frame (``live`` warms up), as in a real session. Then each stage's time per frame (median and 95th percentile, ms;
`LiveReport.stage_ms`), and beside them the peer in the same run: the official mediapipe 0.10.21 Holistic
(landmarks only, ``model_complexity=1``) on the same clip frame after frame, in its own venv (``--mediapipe-python``
or ``$JAXMOCAP_MEDIAPIPE_PYTHON``, as `bench/detect.py`), its frames/s and time per frame.
"""

import argparse
import json
import os
import platform
import socket
import sys
import tempfile
import threading
import time
import urllib.parse
import urllib.request
from pathlib import Path

import jax
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from bench.accuracy import VIEWS  # noqa: E402  (the shipped views)
from bench.detect import MEDIAPIPE_ENV, PEER, mediapipe_python, run_peer  # noqa: E402

CLIP = VIEWS["cam01"]
LOOPS = 6
PEER_FRAMES = 100  # the clip's frames, each once, for the peer's time per frame
BODY_JOINTS = np.arange(22)  # SMPL-X's pelvis to wrists


def agreement_mm(model, live_motion: dict, offline_motion: dict, first_frame: int = 0) -> tuple[float, int]:
    """Mean PA-MPJPE (mm) of the body joints between a live recording and an offline motion of the same video
    from its frame ``first_frame``, over the frames valid in both (a recording's rows are its ``frame_index``);
    and how many frames that is."""
    import smplx_jax
    from jaxmocap.motion import motion_params
    from train.metrics import pa_mpjpe

    rows = np.asarray(live_motion["frame_index"]) - first_frame
    inside = (rows >= 0) & (rows < len(offline_motion["valid"]))
    both = np.flatnonzero(inside & np.asarray(live_motion["valid"]))
    both = both[np.asarray(offline_motion["valid"])[rows[both]]]
    joints = jax.vmap(smplx_jax.forward_joints, in_axes=(None, 0))
    ours = np.asarray(joints(model, motion_params(live_motion, model.num_expression, both)))[:, BODY_JOINTS]
    theirs = np.asarray(joints(model, motion_params(offline_motion, model.num_expression, rows[both])))
    errors = pa_mpjpe(ours, theirs[:, BODY_JOINTS], np.ones(ours.shape[:2], bool))
    return float(np.mean(errors) * 1000), len(both)


def _watch(url: str, stop: threading.Event, seen: list) -> None:
    """A viewer of the page at ``url``: reads its MJPEG stream until ``stop``, counting the frames it got."""
    with urllib.request.urlopen(urllib.parse.urljoin(url, "stream.mjpg"), timeout=10) as stream:
        while not stop.is_set():
            line = stream.readline()
            if not line:  # the session has ended
                return
            if line.startswith(b"Content-Length:"):
                stream.readline()
                stream.read(int(line.split(b":")[1]))
                seen.append(1)


class ThreadCpu:
    """Each thread's CPU time from `start` to `stop` (Linux: ``/proc/self/task``, sampled every ``period`` s, so a
    thread that ends keeps its last sample), summed by name: Python's threads by their names (``jaxmocap-detect``,
    ``MainThread``: the solve), native ones by the kernel's (``tf_XLAEigen``: XLA's, ``av:h264:*``: FFmpeg's decoding,
    ``python``: unnamed ones, LiteRT's workers among them). Empty where there is no ``/proc``."""

    def __init__(self, period: float = 0.2):
        self.period, self.names, self.first, self.last = period, {}, {}, {}
        self._stop, self._thread = threading.Event(), threading.Thread(target=self._sample, daemon=True)

    @staticmethod
    def _now() -> dict[int, tuple[str, float]]:
        tick, out = os.sysconf("SC_CLK_TCK"), {}
        for tid in os.listdir("/proc/self/task") if os.path.isdir("/proc/self/task") else ():
            try:
                comm = Path(f"/proc/self/task/{tid}/comm").read_text().strip()
                fields = Path(f"/proc/self/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()
            except OSError:  # ended meanwhile
                continue
            out[int(tid)] = (comm, (int(fields[11]) + int(fields[12])) / tick)  # utime + stime
        return out

    def _sample(self) -> None:
        while True:
            self.names.update({t.native_id: t.name for t in threading.enumerate()})
            self.last.update(self._now())
            if self._stop.wait(self.period):
                return

    def start(self) -> None:
        self.first, self.began = self._now(), time.perf_counter()
        self._thread.start()

    def stop(self) -> dict[str, float]:
        """CPU seconds by thread name since `start` (``seconds``: the time since)."""
        self._stop.set()
        self._thread.join()
        self.last.update(self._now())
        self.seconds = time.perf_counter() - self.began
        total: dict[str, float] = {}
        for tid, (comm, seconds) in self.last.items():
            name = self.names.get(tid, comm)
            total[name] = total.get(name, 0.0) + seconds - self.first.get(tid, (comm, 0.0))[1]
        return {name: seconds for name, seconds in sorted(total.items(), key=lambda kv: -kv[1]) if seconds > 0}


def session(loops: int, watched: bool) -> dict:
    from jaxmocap.live import LiveConfig, live

    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(0.5)
    stop, seen, messages, threads, cpu = threading.Event(), [], [], [], ThreadCpu()

    def started(url):
        cpu.start()  # capture starts: compiling is over
        if watched:
            threads.append(threading.Thread(target=_watch, args=(url, stop, seen), daemon=True))
            threads.append(threading.Thread(target=_receive, args=(receiver, stop, messages), daemon=True))
            for t in threads:
                t.start()

    config = LiveConfig(CLIP, realtime=True, loops=loops, progress=False, serve=0 if watched else None,
                        udp=receiver.getsockname() if watched else None)
    report = live(config, started)
    thread_cpu = cpu.stop()
    stop.set()
    for t in threads:
        t.join(timeout=5)
    receiver.close()
    return dict(read=report.read, solved=report.solved, dropped=report.dropped, seconds=report.seconds,
                fps=report.fps, latency_median_ms=float(np.median(report.latency_ms)),
                latency_p95_ms=float(np.percentile(report.latency_ms, 95)), viewer_frames=len(seen),
                udp_messages=len(messages), thread_cpu_s=thread_cpu, thread_cpu_window_s=cpu.seconds,
                stages={name: dict(
                    median_ms=float(np.median(ms)), p95_ms=float(np.percentile(ms, 95)), frames=len(ms))
                    for name, ms in report.stage_ms.items()})


def _receive(receiver: socket.socket, stop: threading.Event, messages: list) -> None:
    while not stop.is_set():
        try:
            messages.append(receiver.recv(65536))
        except TimeoutError:
            continue


def agreement(video: Path) -> dict:
    """``video`` solved live frame by frame (every frame) against ``jaxmocap run`` on it, both on the live
session's landmark model (BlazePose full), so that the two solves, not two detectors, are compared."""
    import smplx_jax
    from jaxmocap.live import LiveConfig, live
    from jaxmocap.motion import read_motion
    from jaxmocap.pipeline import RunConfig, run

    model = smplx_jax.load_model(smplx_jax.default_model_path())
    with tempfile.TemporaryDirectory() as tmp:
        config = LiveConfig(video, record=Path(tmp) / "live", progress=False)
        live(config)
        run(RunConfig(video, overlay=False, progress=False, landmarks=config.landmarks), Path(tmp) / "run")
        ours, theirs = (read_motion(Path(tmp) / name / "motion.npz") for name in ("live", "run"))
    error, frames = agreement_mm(model, ours, theirs)
    return dict(pa_mpjpe_mm=error, frames=frames)


def main():
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results"))
    parser.add_argument("--quick", action="store_true", help="the clip twice per row")
    parser.add_argument("--mediapipe-python", default=os.environ.get(MEDIAPIPE_ENV),
                        help=f"the peer's Python (default: ${MEDIAPIPE_ENV})")
    args = parser.parse_args()
    loops = 2 if args.quick else LOOPS
    peer = run_peer(mediapipe_python(args.mediapipe_python), PEER, CLIP, PEER_FRAMES)["results"].get("holistic")
    holistic = None if peer is None else dict(fps=1000 / peer[0], ms_per_frame=peer[0])
    rows = {"as live, 60 fps": session(loops, watched=False),
            "as live, page watched + UDP": session(loops, watched=True)}
    close = {view: agreement(video) for view, video in VIEWS.items()}

    print(f"\njaxmocap live, {CLIP.name} played {loops}x at 60 frames/s, {os.cpu_count()} CPUs, {platform.machine()}")
    print(f"{'':<30}{'frames/s':>9}{'median ms':>10}{'p95 ms':>8}{'solved':>8}{'dropped':>8}{'viewer':>8}{'udp':>6}")
    for name, r in rows.items():
        print(f"{name:<30}{r['fps']:>9.1f}{r['latency_median_ms']:>10.0f}{r['latency_p95_ms']:>8.0f}{r['solved']:>8}"
              f"{r['dropped']:>8}{r['viewer_frames']:>8}{r['udp_messages']:>6}")
    if holistic is not None:
        print(f"{'mediapipe Holistic (landmarks)':<30}{holistic['fps']:>9.1f}{holistic['ms_per_frame']:>10.0f}")
        for name, r in rows.items():
            print(f"{name}: {r['fps'] / holistic['fps']:.2f}x Holistic's frames/s, median latency "
                  f"{r['latency_median_ms'] / holistic['ms_per_frame']:.2f}x its time per frame")
    print(f"\n{'stage (ms a frame)':<30}" + "".join(f"{name[:20]:>22}" for name in rows))
    for stage in sorted({s for r in rows.values() for s in r["stages"]}):
        cells = [r["stages"].get(stage) for r in rows.values()]
        print(f"{stage:<30}" + "".join(
            f"{'-':>22}" if c is None else f"{c['median_ms']:>10.1f} (p95 {c['p95_ms']:>5.1f})" for c in cells))
    print(f"\n{'thread (CPU ms a frame solved)':<30}" + "".join(f"{name[:20]:>22}" for name in rows))
    for thread in sorted({t for r in rows.values() for t in r["thread_cpu_s"]},
                         key=lambda t: -max(r["thread_cpu_s"].get(t, 0.0) for r in rows.values())):
        cells = [1000 * r["thread_cpu_s"].get(thread, 0.0) / max(r["solved"], 1) for r in rows.values()]
        if max(cells) >= 0.5:
            print(f"{thread[:30]:<30}" + "".join(f"{c:>22.1f}" for c in cells))
    print(f"{'cores busy (of ' + str(os.cpu_count()) + ')':<30}" + "".join(
        f"{sum(r['thread_cpu_s'].values()) / r['thread_cpu_window_s']:>22.2f}" for r in rows.values()))
    for view, c in close.items():
        print(f"{view}: live against the offline run, every frame: PA-MPJPE {c['pa_mpjpe_mm']:.1f} mm over "
              f"{c['frames']} frames (body joints)")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "live.json").write_text(json.dumps(dict(benchmark="live", cpus=os.cpu_count(), loops=loops,
                                                        rows=rows, holistic=holistic, agreement=close), indent=2))
    print(f"wrote {args.out / 'live.json'}")


if __name__ == "__main__":
    from jaxmocap.xla_options import configure_process

    configure_process()  # a command of the project: its process's settings before JAX starts
    main()
