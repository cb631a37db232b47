"""The ``jaxmocap`` command line."""

import argparse
import contextlib
import functools
import signal
import sys
from pathlib import Path

from jaxmocap.compile_cache import use_compilation_cache
from jaxmocap.errors import InputError
from jaxmocap.signals import Terminated, handling, interrupt_of, interrupts_kept


@contextlib.contextmanager
def _sigterm_interrupts():
    """Inside, SIGTERM (``kill``, ``timeout``, a job scheduler or container stopping the command) raises
    KeyboardInterrupt (`Terminated`) where Ctrl-C would, so that it stops a command as cleanly (atomic writes rolled
    back, stored chunks kept, a batch's videos listed as stopped, a live session's recording written); the list
    yielded holds the signal once it came, which tells the two apart."""
    received = []

    def interrupt(signum, frame):
        received.append(signum)
        raise Terminated

    with handling(interrupt, signal.SIGTERM):
        yield received


def _cmd_model(args):
    from smplx_jax.default_model import write_default_model

    write_default_model(args.out)
    print(f"wrote the default body model to {args.out}")
    if args.render:
        from jaxmocap.demo import render_body_model

        for path in render_body_model(args.out, args.render):
            print(f"wrote {path}")


def _print_report(report, hands: bool = False):
    seconds = dict(report.seconds)
    total = sum(seconds.values())
    stages = ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items())
    seen = f", BlazePose {report.landmarks}" if report.landmarks else ""
    print(f"{report.frames} frames ({report.valid} with a {'hand' if hands else 'person'}{seen}) in {total:.1f} s "
          f"({report.frames / max(total, 1e-9):.1f} frames/s): {stages}")
    folders = {}
    for path in report.written:
        folders.setdefault(Path(path).parent, []).append(path)
    for folder, paths in folders.items():
        print(f"wrote {len(paths)} files in {folder}/" if len(paths) > 3 else "\n".join(f"wrote {p}" for p in paths))
    if report.camera:
        print(report.camera)
    if len(report.people) > 1:
        print(f"{len(report.people)} {'hands' if hands else 'people'} tracked: {', '.join(map(str, report.people))}")


def _run_config(args, source):
    """The `RunConfig` of ``source`` from `_run_options`' arguments (``run``'s and ``batch``'s)."""
    from jaxmocap.pipeline import RunConfig

    return RunConfig(
        source, mode=args.mode, model=args.model, weights=args.weights, integration=args.integration,
        hand_boxes=args.hand_boxes, keypoints=args.keypoints, max_people=args.max_people, max_hands=args.max_hands,
        landmarks=args.landmarks, start=args.start, end=args.end, stride=args.stride, chunk_size=args.chunk,
        iterations=args.iterations, focal_length=args.focal_length, camera=args.camera, smooth=not args.no_smooth,
        overlay=not args.no_overlay, exports=tuple(f for f in args.export.split(",") if f),
        frankmocap_pkl=args.frankmocap_pkl, save_frames=args.save_frames, progress=not args.quiet)


def _cmd_run(args):
    from jaxmocap.pipeline import run

    _print_report(run(_run_config(args, args.input), args.out), hands=args.mode == "hands")


def _cmd_batch(args):
    from jaxmocap.batch import BatchConfig, batch, read_manifest

    inputs = list(args.inputs) + ([] if args.manifest is None else read_manifest(args.manifest))
    config = BatchConfig(tuple(inputs), _run_config(args, ""), workers=args.workers, address=args.address)
    report = batch(config, args.out)
    print(report.summary())
    return 1 if report.failed else 0


def _cmd_demo(args):
    from jaxmocap.demo import demo

    _print_report(demo(args.out, frankmocap_pkl=args.frankmocap_pkl))


def _cmd_live(args):
    from jaxmocap.live import LiveConfig, live
    from jaxmocap.live.stream import parse_address
    from jaxmocap.live.viewer import is_loopback

    try:
        udp = None if args.udp is None else parse_address(args.udp)
    except ValueError as err:
        raise InputError(f"--udp: {err}") from None
    config = LiveConfig(args.source, mode=args.mode, realtime=args.realtime, loops=args.loops,
                        max_people=args.max_people, max_hands=args.max_hands, landmarks=args.landmarks,
                        serve=args.serve, host=args.host, udp=udp, record=args.record, model=args.model,
                        focal_length=args.focal_length, max_frames=args.frames, progress=not args.quiet)

    def started(url):
        where = f"; watch at {url}" if url is not None else ""
        print(f"live: capturing {args.source}{where} (Ctrl-C stops)", file=sys.stderr, flush=True)
        if url is not None and not is_loopback(args.host):
            print(f"live: the camera is visible on the network at {args.host} to anyone with this link",
                  file=sys.stderr, flush=True)

    report = live(config, started)
    print(report.summary())
    for path in report.written:
        print(f"wrote {path}")


def _cmd_detect(args):
    if args.no_hands and args.mode == "hands":
        raise InputError("--no-hands (--mode body) cannot go with --mode hands")
    if args.max_hands < 1:
        raise InputError(f"--max-hands must be positive, got {args.max_hands}")
    if args.mode == "hands":
        from jaxmocap.detect.hand_json import detect_hands_media

        written = detect_hands_media(args.input, args.out, overlay=args.overlay, progress=not args.quiet,
                                     max_hands=args.max_hands, model_dir=args.models)
        seen = ""
    else:
        from jaxmocap.detect import detect_media
        from jaxmocap.detect.models import available_landmarks

        landmarks = available_landmarks(args.landmarks, args.models)
        written = detect_media(args.input, args.out, overlay=args.overlay, progress=not args.quiet,
                               max_people=args.max_people, model_dir=args.models,
                               hands=args.mode == "whole" and not args.no_hands, landmarks=landmarks)
        seen = f" (BlazePose {landmarks})"
    print(f"wrote {len(written)} OpenPose JSON file(s) to {args.out}{seen}")


def _cmd_fit(args):
    from jaxmocap.pipeline.fit_folder import fit_keypoint_folder

    path = fit_keypoint_folder(args.keypoints, args.out, model_path=args.model, iterations=args.iterations,
                               init=args.init, smooth=not args.no_smooth, image_size=args.image_size,
                               focal_length=args.focal_length, fps=args.fps, progress=not args.quiet)
    print(f"wrote {path}")


def _cmd_export(args):
    from jaxmocap.export import export_motion

    path = export_motion(args.motion, args.format, args.out, model_path=args.model, focal_px=args.focal,
                         frame=args.frame)
    print(f"wrote {path}")


def _cmd_bench(args):
    from jaxmocap.benchmarks import run_benchmarks

    run_benchmarks(args.only, args.out, quick=args.quick)


def _cmd_convert_frankmocap(args):
    from jaxmocap.regressors import convert_frankmocap

    for path in convert_frankmocap(args.hand, args.hand_mean, args.body, args.out):
        print(f"wrote {path}")


def _landmarks_option(p, default: str) -> None:
    from jaxmocap.detect.models import LANDMARK_MODELS

    p.add_argument("--landmarks", choices=tuple(LANDMARK_MODELS), default=default,
                   help="BlazePose's landmark model: heavy (most accurate), full or lite (fastest); heavy and lite are "
                        "fetched with npm on first use, full where they cannot be (default: %(default)s)")


def _mode_options(p) -> None:
    """``--mode`` and ``--max-hands``, the same for ``run``, ``detect`` and ``live``."""
    p.add_argument("--mode", choices=("whole", "body", "hands"), default="whole",
                   help="whole: body and hands; body: no hand model runs (faster, hands flat); hands: hands alone, "
                        "no body needed (default: %(default)s)")
    p.add_argument("--max-hands", type=int, default=2, metavar="N",
                   help="hands tracked at most in --mode hands (default: %(default)s)")


def _run_options(p) -> None:
    """Every option of ``run`` but its input and ``--out``: ``run``'s and ``batch``'s (`_run_config`)."""
    _mode_options(p)
    _landmarks_option(p, "heavy")
    p.add_argument("--model", type=Path, default=None, help="SMPL-X model file (default: the built-in model)")
    p.add_argument("--weights", type=Path, default=None, help="FrankMocap regressors from convert-frankmocap")
    p.add_argument("--integration", choices=("optimize", "copy-paste", "eft"), default="optimize",
                   help="how body and hands are merged (copy-paste and eft need --weights; default: %(default)s)")
    p.add_argument("--hand-boxes", choices=("keypoints", "body"), default="keypoints",
                   help="hand crops from the detector's hand keypoints, or (with --weights; no hand detector) from "
                        "the body regressor's projected hands, FrankMocap's fast mode (default: %(default)s)")
    p.add_argument("--frankmocap-pkl", action="store_true",
                   help="also FrankMocap's per-frame prediction pickles in DIR/mocap/ (its --save_pred_pkl)")
    p.add_argument("--save-frames", action="store_true",
                   help="also the video's frames as DIR/frames/<frame:05d>.jpg, the images FrankMocap's pickles name")
    p.add_argument("--max-people", type=int, default=4, metavar="N",
                   help="people tracked at most, each with an identity and DIR/people/<id>/motion.npz; DIR/motion.npz "
                        "is the one seen in most frames (default: %(default)s)")
    p.add_argument("--keypoints", type=Path, default=None,
                   help="OpenPose JSON folder of one person to fit to instead of the detector's 2D keypoints")
    p.add_argument("--start", type=int, default=0, help="first frame (default: 0)")
    p.add_argument("--end", type=int, default=None, help="stop before this frame")
    p.add_argument("--stride", type=int, default=1, help="use every n-th frame (default: 1)")
    p.add_argument("--export", default="", help="comma-separated: bvh,gltf")
    p.add_argument("--iterations", type=int, default=20, help="fit iterations (default: %(default)s)")
    p.add_argument("--focal-length", type=float, default=None, metavar="PX",
                   help="the camera's focal length in pixels (default: a phone's main camera, 0.75 x the long side)")
    p.add_argument("--camera", choices=("turns", "static"), default="turns",
                   help="turns: a video camera's turns (panning, tilting, handheld) measured from the background, "
                        "the world frame held still through them; static: a camera held still (default: %(default)s)")
    p.add_argument("--chunk", type=int, default=128, help="frames per resumable chunk (default: %(default)s)")
    p.add_argument("--no-smooth", action="store_true",
                   help="no motion between frames: each fitted as an unrelated image (--mode hands: no smoothing)")
    p.add_argument("--no-overlay", action="store_true", help="no overlay video")
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(allow_abbrev=False, prog="jaxmocap", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    command = functools.partial(commands.add_parser, allow_abbrev=False)  # a mistyped option is an error

    p = command("demo", help="the main job on the bundled sample clip: motion, overlay video, exports")
    p.add_argument("--out", type=Path, default=Path("jaxmocap_demo"), help="output folder (default: %(default)s)")
    p.add_argument("--frankmocap-pkl", action="store_true",
                   help="also FrankMocap's per-frame prediction pickles in DIR/mocap/")
    p.set_defaults(run=_cmd_demo)

    p = command("run", help="video, image folder, image or webcam -> DIR/motion.npz, overlay, exports")
    p.add_argument("input", help="video file, image folder, single image or webcam index")
    p.add_argument("--out", type=Path, default=Path("jaxmocap_out"), help="output folder (default: %(default)s)")
    _run_options(p)
    p.set_defaults(run=_cmd_run)

    p = command("batch", help="many videos as Ray tasks -> DIR/<stem>/ each as `run` writes it, DIR/batch.json")
    p.add_argument("inputs", nargs="*", metavar="INPUT", help="video files, image folders or stream URLs")
    p.add_argument("--manifest", type=Path, default=None, metavar="FILE", help="more inputs, one per line")
    p.add_argument("--out", type=Path, required=True, metavar="DIR",
                   help="output folder: DIR/<stem>/ per video, DIR/batch.json")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="videos solved at once (default: this machine's cores; with --address, the cluster's)")
    p.add_argument("--address", default=None, metavar="ADDR",
                   help="a Ray cluster's address (HOST:PORT of `ray start --head`); default: a local Ray on "
                        "127.0.0.1 for this batch alone")
    _run_options(p)
    p.set_defaults(run=_cmd_batch)

    p = command("live", help="webcam, stream or file -> SMPL-X frame by frame, on a web page and over UDP")
    p.add_argument("source", help="webcam index (0), stream URL, or video file")
    _mode_options(p)
    _landmarks_option(p, "full")
    p.add_argument("--realtime", action="store_true",
                   help="play a file at its own frame rate, as if live (frames dropped when behind)")
    p.add_argument("--loop", dest="loops", type=int, default=1, metavar="N",
                   help="play a file N times, 0 for ever (default: %(default)s)")
    p.add_argument("--serve", type=int, default=None, metavar="PORT", help="show the overlay on a web page at PORT")
    p.add_argument("--host", default="127.0.0.1",
                   help="address the page listens on (default: %(default)s, this machine only; any other puts the "
                        "camera on the network, behind a token printed at start)")
    p.add_argument("--udp", default=None, metavar="HOST:PORT",
                   help="send each frame's SMPL-X parameters as a JSON line (docs/formats.md, \"Live stream\")")
    p.add_argument("--record", type=Path, default=None, metavar="DIR",
                   help="write DIR/motion.npz (and DIR/people/<id>/motion.npz; DIR/hands.npz with --mode hands) as it "
                        "goes: the frames so far every few seconds, the rest at the end")
    p.add_argument("--max-people", type=int, default=1, metavar="N", help="people tracked at most (default: 1)")
    p.add_argument("--frames", type=int, default=None, metavar="N", help="stop after N frames solved")
    p.add_argument("--model", type=Path, default=None, help="SMPL-X model file (default: the built-in model)")
    p.add_argument("--focal-length", type=float, default=None, metavar="PX",
                   help="the camera's focal length in pixels (default: 0.75 x the long side)")
    p.add_argument("--quiet", action="store_true", help="no live status line")
    p.set_defaults(run=_cmd_live)

    p = command("detect", help="2D keypoints (BODY_25 + hands) as OpenPose JSON, one file per frame")
    p.add_argument("input", help="video file, image folder, single image or webcam index")
    p.add_argument("--out", type=Path, required=True, help="output folder for the JSON files")
    _mode_options(p)
    _landmarks_option(p, "heavy")
    p.add_argument("--overlay", action="store_true", help="also draw the skeletons (images or a video)")
    p.add_argument("--max-people", type=int, default=4, help="people per frame, each with a person_id in a video "
                                                              "(default: %(default)s)")
    p.add_argument("--no-hands", action="store_true", help="body keypoints only, as --mode body")
    p.add_argument("--models", type=Path, default=None, help="folder holding mediapipe's .tflite files "
                                                                    "(jaxmocap.detect.models)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=_cmd_detect)

    p = command("fit", help="fit SMPL-X to OpenPose JSON keypoints alone -> DIR/motion.npz")
    p.add_argument("keypoints", type=Path, help="folder of OpenPose JSON files, one per frame (sorted by name)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--model", type=Path, default=None, help="SMPL-X model file (default: the built-in model)")
    p.add_argument("--iterations", type=int, default=None,
                   help="the cap on each window's Levenberg-Marquardt steps; a window stops once converged "
                        "(default: the clip fit's own, jaxmocap.integrate.ClipConfig.iterations)")
    p.add_argument("--init", type=Path, default=None, help="motion.npz to start from (same frames)")
    p.add_argument("--no-smooth", action="store_true",
                   help="the files are unrelated images, not a video's frames: no motion between them")
    p.add_argument("--image-size", type=int, nargs=2, metavar=("W", "H"), default=None,
                   help="image size in pixels (OpenPose JSON has none; default: inferred from the keypoints)")
    p.add_argument("--focal-length", type=float, default=None, metavar="PX",
                   help="the camera's focal length in pixels (default: 0.75 x the long side)")
    p.add_argument("--fps", type=float, default=30.0,
                   help="the frames' rate: the motion's time step, stored in motion.npz (default: %(default)s)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=_cmd_fit)

    p = command("export", help="a motion.npz as BVH (skeleton) or glTF 2.0 (skinned mesh) animation; "
                                "a hands.npz as glTF")
    p.add_argument("motion", type=Path, help="motion.npz or hands.npz")
    p.add_argument("--format", choices=("bvh", "gltf"), required=True)
    p.add_argument("--out", type=Path, required=True, help="file to write (.bvh; .glb binary or .gltf JSON)")
    p.add_argument("--model", type=Path, default=None, help="the body model the motion was made with (default model)")
    p.add_argument("--focal", type=float, default=None, help="focal length in pixels (default: image diagonal)")
    p.add_argument("--frame", choices=("world", "camera"), default="world",
                   help="world: on the floor (y up, the floor y = 0) where the motion has a world frame; camera: "
                        "the camera's frame turned y up (default: %(default)s)")
    p.set_defaults(run=_cmd_export)

    p = command("model", help="write the license-free default body model as an SMPL-X .npz")
    p.add_argument("--out", type=Path, required=True, help="file to write, e.g. models/smplx/SMPLX_NEUTRAL.npz")
    p.add_argument("--render", type=Path, default=None, help="also render it (rest and example pose) into this folder")
    p.set_defaults(run=_cmd_model)

    p = command("convert-frankmocap", help="FrankMocap's PyTorch checkpoints -> our weights (needs torch)")
    p.add_argument("--hand", type=Path, required=True, help="hand module checkpoint, pose_shape_best.pth")
    p.add_argument("--hand-mean", type=Path, required=True, help="the hand's mean_mano_params.pkl")
    p.add_argument("--body", type=Path, required=True, help="body module checkpoint (SPIN/HMR .pt)")
    p.add_argument("--out", type=Path, required=True, help="output folder (regressors.json, hand.npz, body.npz)")
    p.set_defaults(run=_cmd_convert_frankmocap)

    p = command("bench", help="the benchmark suite, side by side with peers (needs a source checkout)")
    p.add_argument("--only", nargs="*", default=None, help="benchmark names, e.g. body_model")
    p.add_argument("--out", type=Path, default=Path("bench/results"), help="folder for JSON results")
    p.add_argument("--quick", action="store_true", help="fewer repetitions")
    p.set_defaults(run=_cmd_bench)
    return parser


def main(argv=None) -> int:
    """The ``jaxmocap`` command on ``argv`` (default ``sys.argv[1:]``); returns the exit code: 0 done, 2 bad input
    (a one-line error), 130 / 143 interrupted by Ctrl-C / SIGTERM, 1 a batch with a failed video."""
    from smplx_jax import ModelFileError

    args = _parser().parse_args(argv)
    if args.command != "bench":  # benchmarks time first runs, compilation included
        use_compilation_cache()
    with _sigterm_interrupts() as terminated, interrupts_kept():
        try:
            code = args.run(args)
        except BaseException as err:
            if interrupt_of(err) is None:  # (an error raised by, or while stopping on, Ctrl-C: interrupted)
                if not isinstance(err, (InputError, ModelFileError, OSError)):
                    raise
                print(f"jaxmocap {args.command}: error: {err}", file=sys.stderr)
                return 2
            # `live` stops on Ctrl-C (or SIGTERM) by itself; elsewhere it interrupts
            resume = "; run the same command again to resume" if args.command in ("run", "demo", "batch") else ""
            print(f"jaxmocap {args.command}: {'terminated' if terminated else 'interrupted'}{resume}",
                  file=sys.stderr)
            return 128 + (signal.SIGTERM if terminated else signal.SIGINT)
    return code or 0  # `batch`: 1 when a video failed


if __name__ == "__main__":  # python -m jaxmocap.cli: the `jaxmocap` command (`command.entry`)
    from jaxmocap.command import entry

    entry()
