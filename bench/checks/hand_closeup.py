"""Make ``tests/data/pose2sim_hand_closeup.mp4``: the bundled Pose2Sim clip cropped around the person's right hand,
a hand close-up in motion for the hands-only tests and benchmark (same source and licence as the clip).

    python bench/checks/hand_closeup.py [--out tests/data/pose2sim_hand_closeup.mp4]

The whole-body detector finds the hand in each frame; the crop's centre follows it (gaps interpolated, smoothed
over 9 frames), its side is three times the hand's median size, and it is resized to 320 x 320.
"""

import argparse
from pathlib import Path

import cv2
import numpy as np

from jaxmocap.detect import Detector

ROOT = Path(__file__).resolve().parents[2]
CLIP = ROOT / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"
SIZE = 320


def main():
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "tests" / "data" / "pose2sim_hand_closeup.mp4")
    args = parser.parse_args()
    capture = cv2.VideoCapture(str(CLIP))
    fps = capture.get(cv2.CAP_PROP_FPS)
    detector = Detector(static_image_mode=False)
    frames, centres, sizes = [], [], []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        people = detector(frame)
        box = people[0].right_hand_box if people else None
        frames.append(frame)
        centres.append(np.full(2, np.nan) if box is None else (box[:2] + box[2:]) / 2)
        sizes.append(np.nan if box is None else max(box[2] - box[0], box[3] - box[1]))
    centres = np.asarray(centres)
    seen = np.isfinite(centres[:, 0])
    t = np.arange(len(frames))
    centres = np.stack([np.interp(t, t[seen], centres[seen, k]) for k in range(2)], axis=1)
    kernel = np.ones(9) / 9
    padded = np.pad(centres, ((4, 4), (0, 0)), mode="edge")
    centres = np.stack([np.convolve(padded[:, k], kernel, mode="valid") for k in range(2)], axis=1)
    half = 1.5 * np.nanmedian(sizes)
    writer = cv2.VideoWriter(str(args.out), cv2.VideoWriter_fourcc(*"mp4v"), fps, (SIZE, SIZE))
    for frame, (cx, cy) in zip(frames, centres):
        src = np.float32([[cx - half, cy - half], [cx + half, cy - half], [cx - half, cy + half]])
        dst = np.float32([[0, 0], [SIZE, 0], [0, SIZE]])
        writer.write(cv2.warpAffine(frame, cv2.getAffineTransform(src, dst), (SIZE, SIZE), flags=cv2.INTER_CUBIC,
                                    borderMode=cv2.BORDER_REPLICATE))
    writer.release()
    print(f"wrote {args.out}: {len(frames)} frames, {SIZE} x {SIZE}, the hand seen by the detector in "
          f"{int(seen.sum())}")


if __name__ == "__main__":
    main()
