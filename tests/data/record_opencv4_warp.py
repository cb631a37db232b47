"""Record OpenCV 4's ``cv2.warpPerspective`` (bilinear, both borders) on crops like the detector's, as the reference
for `jaxmocap.detect.roi.warp_perspective` (run where ``cv2`` is OpenCV 4, e.g. the mediapipe venv of
``record_mediapipe_golden.py``, whose opencv-contrib-python is 4.11):

    ~/venvs/mediapipe/bin/python tests/data/record_opencv4_warp.py

Writes ``tests/data/opencv4_warp.npz``: ``image`` (a frame of ``pose2sim_cam01_f000.jpg``, 1/4 size), ``matrices``
(N, 3, 3) and ``replicate`` / ``zero`` (N, 64, 64, 3) the warps with each border, and ``opencv_version``.
"""

import os

import cv2
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SIZE = 64
# rotated squares (centre x, y, side in pixels, degrees): inside the image, across its edges, turned far, small
RECTS = ((135, 240, 160, 0.0), (135, 240, 200, 11.9), (40, 300, 150, -40.5), (250, 60, 120, 29.0),
         (135, 240, 330, 176.0), (100, 200, 33.3, -7.25))


def main() -> None:
    assert cv2.__version__.startswith("4."), f"needs OpenCV 4, this is {cv2.__version__}"
    image = cv2.imread(os.path.join(HERE, "pose2sim_cam01_f000.jpg"))
    image = cv2.resize(image, (image.shape[1] // 4, image.shape[0] // 4), interpolation=cv2.INTER_AREA)
    corners = np.array([[0, SIZE], [0, 0], [SIZE, 0], [SIZE, SIZE]], np.float32)
    matrices = np.stack([cv2.getPerspectiveTransform(cv2.boxPoints(((x, y), (side, side), degrees)), corners)
                         for x, y, side, degrees in RECTS])
    warps = {name: np.stack([cv2.warpPerspective(image, m, (SIZE, SIZE), flags=cv2.INTER_LINEAR, borderMode=border)
                             for m in matrices])
             for name, border in (("replicate", cv2.BORDER_REPLICATE), ("zero", cv2.BORDER_CONSTANT))}
    np.savez_compressed(os.path.join(HERE, "opencv4_warp.npz"), image=image, matrices=matrices,
                        opencv_version=cv2.__version__, **warps)


if __name__ == "__main__":
    main()
