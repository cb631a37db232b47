"""The overlay's side view of each shipped view and its mirror, to look at (issue 24: no frame where the body turns
round): ``jaxmocap run`` of each, then every fifth frame's side view in one strip per case.

    python bench/side_views.py [--out bench/results] [--image FILE] [--quick]

Prints per case the identities, valid frames, the largest turn of the global orientation between consecutive
frames and the share of joint-frames turning > 45° (`accuracy.rotation_coherence`); writes the strips to
``--image`` (default ``<out>/side_views.jpg``; docs/side_views.jpg is one) and the figures to
``<out>/side_views.json``. ``--quick``: cam01 and its mirror only.
"""

import argparse
import json
import platform
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from bench.accuracy import VIEWS, rotation_coherence, write_variant  # noqa: E402

EVERY = 5  # frames between thumbnails
THUMB = (68, 120)  # width, height of a thumbnail of the side view (the overlay's right half)


def side_strip(overlay: Path, label: str) -> np.ndarray:
    """Every `EVERY`-th frame's side view, numbered, after a label."""
    from jaxmocap.frame_source import open_media

    thumbs = []
    for index, frame in open_media(overlay, stride=EVERY)[1]:
        thumb = cv2.resize(frame[:, frame.shape[1] // 2:], THUMB, interpolation=cv2.INTER_AREA)
        cv2.putText(thumb, str(index), (2, 11), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (0, 0, 200), 1)
        thumbs.append(thumb)
    name = np.full((THUMB[1], 110, 3), 255, np.uint8)
    cv2.putText(name, label, (4, THUMB[1] // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1)
    return np.hstack([name, *thumbs])


def main():
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results"))
    parser.add_argument("--image", type=Path, help="the strips (default: <out>/side_views.jpg)")
    parser.add_argument("--quick", action="store_true", help="cam01 and its mirror only")
    args = parser.parse_args()
    image = args.image or args.out / "side_views.jpg"
    from jaxmocap.motion import read_motion
    from jaxmocap.pipeline import RunConfig, run

    results, strips = {}, []
    for view, video in list(VIEWS.items())[:1 if args.quick else None]:
        for case in ("as shot", "mirror"):
            with tempfile.TemporaryDirectory() as work:
                work = Path(work)
                source = video if case == "as shot" else write_variant(video, case, work / "variant.mp4", 0.0)
                run(RunConfig(source, progress=False), work / "run")
                motion = read_motion(work / "run" / "motion.npz")
                results[f"{view} {case}"] = dict(
                    ids=len(list((work / "run" / "people").iterdir())), valid_frames=int(motion["valid"].sum()),
                    **rotation_coherence(motion))
                label = view if case == "as shot" else f"{view} mirror"
                strips.append(side_strip(work / "run" / "overlay.mp4", label))
    print(f"\nthe overlay's side view, jaxmocap run of each shipped view and its mirror, {platform.machine()}")
    print(f"{'case':>14} {'ids':>3} {'valid':>5} {'largest global turn':>20} {'> 45°':>7}")
    for case, r in results.items():
        print(f"{case:>14} {r['ids']:>3} {r['valid_frames']:>5} {r['global_turn_largest_deg']:>19.1f}° "
              f"{100 * r['rotation_change_over_45deg']:>6.2f}%")
    width = max(s.shape[1] for s in strips)
    sheet = np.vstack([np.pad(s, ((0, 0), (0, width - s.shape[1]), (0, 0)), constant_values=255) for s in strips])
    for folder in (image.parent, args.out):
        folder.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(image), sheet, [cv2.IMWRITE_JPEG_QUALITY, 85])
    (args.out / "side_views.json").write_text(json.dumps(dict(benchmark="side_views", machine=platform.machine(),
                                                              cases=results), indent=1))
    print(f"wrote {image} and {args.out / 'side_views.json'}")


if __name__ == "__main__":
    from jaxmocap.xla_options import configure_process

    configure_process()  # a command of the project: its process's settings before JAX starts
    main()
