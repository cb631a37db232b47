"""Facts about SMPL-X that every model file shares: joint names, the vertex joints and OpenPose mappings."""

NUM_JOINTS = 55  # skeleton joints
NUM_BODY_JOINTS = 21  # body_pose: joints 1..21
NUM_HAND_JOINTS = 15  # per hand
NUM_OUTPUT_JOINTS = 127  # 55 skeleton + 21 vertex joints + 51 face landmarks

JOINT_NAMES = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle",
    "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "jaw",
    "left_eye", "right_eye",
    *(f"left_{f}{i}" for f in ("index", "middle", "pinky", "ring", "thumb") for i in (1, 2, 3)),
    *(f"right_{f}{i}" for f in ("index", "middle", "pinky", "ring", "thumb") for i in (1, 2, 3)),
)

LEFT_WRIST, RIGHT_WRIST = 20, 21
LEFT_HAND_JOINTS = tuple(range(25, 40))
RIGHT_HAND_JOINTS = tuple(range(40, 55))

# Vertex ids the `smplx` package reads as extra joints 55..75, in its order: face (nose, right eye, left eye,
# right ear, left ear), feet (left big toe, small toe, heel, right big toe, small toe, heel), fingertips
# (left thumb, index, middle, ring, pinky, then right).
VERTEX_JOINT_NAMES = (
    "nose", "right_eye_vertex", "left_eye_vertex", "right_ear", "left_ear",
    "left_big_toe", "left_small_toe", "left_heel", "right_big_toe", "right_small_toe", "right_heel",
    "left_thumb_tip", "left_index_tip", "left_middle_tip", "left_ring_tip", "left_pinky_tip",
    "right_thumb_tip", "right_index_tip", "right_middle_tip", "right_ring_tip", "right_pinky_tip",
)
VERTEX_JOINT_IDS = (
    9120, 9929, 9448, 616, 6,
    5770, 5780, 8846, 8463, 8474, 8635,
    5361, 4933, 5058, 5169, 5286,
    8079, 7669, 7794, 7905, 8022,
)
NUM_LANDMARKS = 51

# OpenPose keypoints as indices into the 127 output joints.
BODY25_FROM_SMPLX = (55, 12, 17, 19, 21, 16, 18, 20, 0, 2, 5, 8, 1, 4, 7, 56, 57, 58, 59, 60, 61, 62, 63, 64, 65)
LEFT_HAND21_FROM_SMPLX = (20, 37, 38, 39, 66, 25, 26, 27, 67, 28, 29, 30, 68, 34, 35, 36, 69, 31, 32, 33, 70)
RIGHT_HAND21_FROM_SMPLX = (21, 52, 53, 54, 71, 40, 41, 42, 72, 43, 44, 45, 73, 49, 50, 51, 74, 46, 47, 48, 75)
OPENPOSE67_FROM_SMPLX = BODY25_FROM_SMPLX + LEFT_HAND21_FROM_SMPLX + RIGHT_HAND21_FROM_SMPLX
