"""Embedded whole-body keypoint detector: mediapipe's BlazePose and hand models run with LiteRT, no mediapipe.

    from jaxmocap.detect import Detector, to_openpose
    people = Detector(static_image_mode=True, max_people=2)(cv2.imread("photo.jpg"))
    keypoints = to_openpose(people)            # (P, 67, 3): BODY_25, left hand 21, right hand 21
    hands = HandTracker(static_image_mode=True)(cv2.imread("hand.jpg"))   # hands alone, no body: [Hand]

``detect_media(input, out_dir)`` writes OpenPose JSON per frame for a video, an image folder or one image;
``detect_hands_media`` the same of hands alone.
"""

from ..frame_source import MediaError
from .detector import Detector, Person
from .hand_json import detect_hands_media
from .hand_tracker import Hand, HandTracker
from .json_output import detect_media, to_openpose
from .models import ModelFileError, ensure_models
from .openpose import read_openpose_json, write_openpose_json

__all__ = [
    "Detector", "Hand", "HandTracker", "Person", "MediaError", "ModelFileError", "detect_hands_media", "detect_media",
    "ensure_models", "read_openpose_json", "to_openpose", "write_openpose_json",
]
