"""Reading frames: video ranges and strides, image folders, webcams, and errors."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from jaxmocap.frame_source import MediaError, open_media

CLIP = Path(__file__).parents[1] / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"


def _direct(indices):
    cap, frames, i = cv2.VideoCapture(str(CLIP)), {}, 0
    while True:
        ok, frame = cap.read()
        if not ok:
            return frames
        if i in indices:
            frames[i] = frame
        i += 1


def test_video_range_and_stride_match_direct_decoding():
    media, frames = open_media(CLIP, start=10, end=40, stride=7)
    got = list(frames)
    assert media.kind == "video" and media.frame_count == 5 and media.size == (1080, 1920)
    assert [i for i, _ in got] == [10, 17, 24, 31, 38]
    expected = _direct({10, 17, 24, 31, 38})
    for i, frame in got:
        np.testing.assert_array_equal(frame, expected[i])


def test_whole_video_and_early_stop():
    media, frames = open_media(CLIP)
    assert media.frame_count == 100 and media.fps == pytest.approx(60.0)
    assert sum(1 for _ in frames) == 100
    _, frames = open_media(CLIP)
    next(frames)
    frames.close()  # stopping early releases the decoding thread


def test_image_folder(tmp_path):
    for k in range(4):
        cv2.imwrite(str(tmp_path / f"img{k}.png"), np.full((20, 30, 3), k, np.uint8))
    media, frames = open_media(tmp_path, start=1, stride=2)
    assert media.kind == "images" and media.stems == ("img1", "img3") and media.size == (30, 20)
    assert [int(f[0, 0, 0]) for _, f in frames] == [1, 3]


def test_errors(tmp_path):
    with pytest.raises(MediaError, match="does not exist"):
        open_media(tmp_path / "nope.mp4")
    with pytest.raises(MediaError, match="cannot open webcam 57"):
        open_media("57")
    with pytest.raises(MediaError, match="bad frame range"):
        open_media(CLIP, start=5, end=5)
    with pytest.raises(MediaError, match="no readable frames from frame 500"):
        open_media(CLIP, start=500)
    (tmp_path / "junk.mp4").write_bytes(b"not a video")
    with pytest.raises(MediaError, match="junk.mp4"):
        open_media(tmp_path / "junk.mp4")
