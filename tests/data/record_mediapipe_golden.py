"""Record the official mediapipe 0.10.21 legacy solutions' landmarks on the test images (run in its own venv).

    python3 -m venv ~/venvs/mediapipe && ~/venvs/mediapipe/bin/pip install mediapipe==0.10.21
    MP=$(~/venvs/mediapipe/bin/python -c 'import mediapipe, os; print(os.path.dirname(mediapipe.__file__))')
    cp ~/.cache/jaxmocap/mediapipe-pose-0.5.1675469404/*.tflite "$MP/modules/pose_landmark/"
    ~/venvs/mediapipe/bin/python tests/data/record_mediapipe_golden.py

The wheel bundles only BlazePose full (``model_complexity=1``); with heavy and lite from the npm package
``@mediapipe/pose@0.5.1675469404`` in its ``modules/pose_landmark/`` (where jaxmocap caches them, the cp above), the
legacy solution runs them too (``model_complexity=2`` and ``0``) instead of trying to download them.

Writes ``tests/data/mediapipe_golden.json``: per image, the pose landmarks (33 × x, y in pixels, z, visibility) of
``mp.solutions.pose.Pose(static_image_mode=True, model_complexity=c)`` for each landmark model (``pose``: full,
``pose_heavy``, ``pose_lite``) and the hands (21 × x, y in pixels, z, with mediapipe's handedness label and score)
of ``mp.solutions.hands.Hands(static_image_mode=True)``; per hand video (`VIDEOS`) and each of its versions
(`versions`: as shot, blurred, mirrored and blurred), the hands found in each frame by
``mp.solutions.hands.Hands(static_image_mode=False, max_num_hands=2)`` and the sha256 of the frames given it.
"""

import hashlib
import json
import os

import cv2
import mediapipe as mp

HERE = os.path.dirname(os.path.abspath(__file__))
POSES = {"pose": 1, "pose_heavy": 2, "pose_lite": 0}  # golden key -> model_complexity
IMAGES = (["messi5.jpg"] + [f"pose2sim_cam01_f{i:03d}.jpg" for i in (0, 20, 40, 60, 80, 99)]
          + ["pose2sim_multi_f050.jpg"])
VIDEOS = ["pose2sim_hand_closeup.mp4"]
BLUR_PX = 2.0  # Gaussian sigma of the blurred versions: a hand a little out of focus or moving


def versions(frames: list) -> dict[str, list]:
    """A video's BGR frames as shot, blurred by `BLUR_PX`, and mirrored (a left hand for a right) and blurred."""
    blurred = [cv2.GaussianBlur(f, (0, 0), BLUR_PX) for f in frames]
    return {"as shot": frames, "blurred": blurred,
            "mirrored, blurred": [cv2.GaussianBlur(cv2.flip(f, 1), (0, 0), BLUR_PX) for f in frames]}


def read_video(path: str) -> list:
    capture, frames = cv2.VideoCapture(path), []
    while (frame := capture.read()[1]) is not None:
        frames.append(frame)
    return frames


def main() -> None:
    out = {"mediapipe_version": mp.__version__, "images": {}}
    poses = {key: mp.solutions.pose.Pose(static_image_mode=True, model_complexity=c) for key, c in POSES.items()}
    with mp.solutions.hands.Hands(static_image_mode=True, max_num_hands=2, model_complexity=1) as hands:
        for name in IMAGES:
            bgr = cv2.imread(os.path.join(HERE, name))
            h, w = bgr.shape[:2]
            rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
            entry = {"width": w, "height": h, "pixels_sha256": hashlib.sha256(bgr.tobytes()).hexdigest(),
                     "hands": []}
            for key, pose in poses.items():
                res = pose.process(rgb)
                entry[key] = None if res.pose_landmarks is None else [
                    [lm.x * w, lm.y * h, lm.z * w, lm.visibility] for lm in res.pose_landmarks.landmark]
            res = hands.process(rgb)
            for lms, cls in zip(res.multi_hand_landmarks or [], res.multi_handedness or []):
                entry["hands"].append({
                    "label": cls.classification[0].label, "score": cls.classification[0].score,
                    "landmarks": [[lm.x * w, lm.y * h, lm.z * w] for lm in lms.landmark]})
            out["images"][name] = entry
            print(name, *(key if entry[key] else f"no {key}" for key in POSES), len(entry["hands"]), "hands")
    for pose in poses.values():
        pose.close()
    out["videos"] = {}
    for name in VIDEOS:
        out["videos"][name] = {}
        for version, frames in versions(read_video(os.path.join(HERE, name))).items():
            digest = hashlib.sha256(b"".join(f.tobytes() for f in frames)).hexdigest()
            with mp.solutions.hands.Hands(static_image_mode=False, max_num_hands=2, model_complexity=1) as hands:
                found = [len(hands.process(cv2.cvtColor(f, cv2.COLOR_BGR2RGB)).multi_hand_landmarks or [])
                         for f in frames]
            out["videos"][name][version] = {"pixels_sha256": digest, "hands_per_frame": found}
            print(name, version, sum(n > 0 for n in found), "of", len(found), "frames with a hand")
    with open(os.path.join(HERE, "mediapipe_golden.json"), "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
