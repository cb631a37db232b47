"""The overlay video: frame count, size, and the mesh drawn where the camera puts it."""

from pathlib import Path

import cv2
import jax
import numpy as np

import smplx_jax
from conftest import load
from jaxmocap.overlay import (
    GROUND,
    OverlayWriter,
    Posed,
    body_up,
    mesh_over_frame,
    people_over_frame,
    person_colour,
    shrunk,
    side_view,
    upright,
)
from jaxmocap.poses import example_pose
from smplx_jax.rotations import rotvec_to_rotmat

CLIP = Path(__file__).parents[1] / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"


def _posed(model):
    flip = np.array([np.pi, 0.0, 0.0], np.float32)  # y up to the image's y down
    params = example_pose().replace(global_orient=flip)
    out = jax.jit(smplx_jax.forward)(model, params)
    return np.asarray(out.vertices), np.asarray(out.joints)


def test_mesh_lands_on_its_projection(default_model_dir):
    model = load(default_model_dir)
    vertices, joints = _posed(model)
    frame = np.zeros((400, 300, 3), np.uint8)
    scale, trans = 150.0, np.array([150.0, 180.0])
    drawn = mesh_over_frame(frame, vertices, np.asarray(model.faces), scale, trans)
    head = np.round(joints[15, :2] * scale + trans).astype(int)  # the head joint is inside the mesh
    assert drawn[head[1], head[0]].max() > 0
    assert drawn[5, 5].max() == 0  # far from the body nothing is drawn
    box = vertices[:, :2] * scale + trans
    covered = np.argwhere(drawn.max(axis=2) > 0)
    assert covered[:, 1].min() >= box[:, 0].min() - 2 and covered[:, 0].max() <= box[:, 1].max() + 2


def test_a_pinhole_camera_draws_a_distant_mesh_as_weak_perspective_does(default_model_dir):
    """Far from a pinhole camera (focal / depth = the weak camera's scale) the two drawings agree; near it, parts
    nearer the camera are drawn bigger."""
    model = load(default_model_dir)
    vertices, _ = _posed(model)
    frame, faces = np.zeros((400, 300, 3), np.uint8), np.asarray(model.faces)
    weak = mesh_over_frame(frame, vertices, faces, 150.0, np.array([150.0, 180.0])).max(axis=2) > 0
    for depth, agree in ((1000.0, 0.99), (2.0, 0.9)):
        pinhole = mesh_over_frame(frame, vertices + [0, 0, depth], faces, 0.0, np.zeros(2), 1.0, 150.0 * depth,
                                  np.array([150.0, 180.0])).max(axis=2) > 0
        iou = (weak & pinhole).sum() / (weak | pinhole).sum()
        assert iou > agree if depth > 100 else iou < agree, (depth, iou)


def test_the_side_view_stands_the_body_up():
    """A body leaning towards the camera (a camera looking down on it) is stood up: its up axis maps to the
    image's up, by a rotation."""
    np.testing.assert_allclose(body_up(np.array([[np.pi, 0.0, 0.0]])), [0, -1, 0], atol=1e-6)  # upright
    for orient in ([np.pi + 0.6, 0.0, 0.0], [np.pi, 0.0, 0.4], [0.0, 0.0, 0.0]):  # leaning; upside down
        up = body_up(np.array([orient]))
        level = upright(up)
        np.testing.assert_allclose(level @ up, [0, -1, 0], atol=1e-6)
        np.testing.assert_allclose(level @ level.T, np.eye(3), atol=1e-6)
        assert np.linalg.det(level) > 0


def test_the_side_view_draws_the_floor_under_the_feet(default_model_dir):
    """A body standing on its floor (the plane of its soles, tilted with it as a camera looking down sees it):
    seen from the side, the ground's rows begin where its feet end, within two pixels, and the body stands up."""
    model = load(default_model_dir)
    vertices, _ = _posed(model)
    tilt = np.asarray(rotvec_to_rotmat(np.array([0.5, 0.0, 0.0], np.float32)), np.float64)
    vertices = vertices @ tilt.T + [0.0, 0.0, 4.0]
    normal = tilt @ [0.0, -1.0, 0.0]  # the body's up in the camera frame
    floor = np.append(normal, -float(np.min(vertices @ normal)))
    size, faces = (300, 400), np.asarray(model.faces)
    view = side_view([Posed(0, vertices, 1.0, np.zeros(2))], faces, size, 150.0, vertices.mean(0), detail=1.0,
                     floor=floor)
    ground_rows = np.flatnonzero(np.all(view[:, 5] == GROUND, -1))
    body = np.argwhere(np.any(view != 235, -1) & np.any(view != GROUND, -1))
    assert len(ground_rows) and abs(ground_rows.min() - (body[:, 0].max() + 1)) <= 2, (ground_rows.min(), body.max(0))
    assert np.ptp(body[:, 0]) > 0.8 * 150.0 * np.ptp(vertices @ normal)  # standing: its height is the view's


def test_overlay_video_frames_and_size(default_model_dir, tmp_path):
    """Every frame written, in order, as composed: the people (none, one, two) over the frame beside their side
    view (up to the mp4's loss)."""
    model = load(default_model_dir)
    vertices, _ = _posed(model)
    cap = cv2.VideoCapture(str(CLIP))
    path = tmp_path / "overlay.mp4"
    with OverlayWriter(path, (1080, 1920), fps=30.0, faces=np.asarray(model.faces)) as writer:
        frames = [cap.read()[1] for _ in range(5)]
        people = [Posed(0, vertices, 700.0, np.array([540.0, 900.0])),
                  Posed(1, vertices + [0.3, 0.0, 0.0], 700.0, np.array([540.0, 900.0]))]
        shown = [(frame, people[:k % 3]) for k, frame in enumerate(frames)]
        writer.write(*shown)
        composed = [writer.compose(*s).astype(float) for s in shown]
    video = cv2.VideoCapture(str(path))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 5
    decoded = [video.read() for _ in range(6)]
    assert all(ok for ok, _ in decoded[:5]) and not decoded[5][0]
    loss = np.array([[np.abs(got.astype(float) - want).mean() for want in composed] for _, got in decoded[:5]])
    print("mean absolute difference, decoded (rows) against composed frames (columns):\n", loss.round(2))
    assert np.array_equal(loss.argmin(axis=1), np.arange(5)) and loss.diagonal().max() < 4.5  # measured 3.0
    for k, (_, got) in enumerate(decoded[:5]):
        assert got.shape == (960, 1080, 3)
        front = (np.abs(got[:, :520].astype(int) - shrunk(frames[k], 0.5)[:, :520]).max(axis=2) > 40).mean()
        side = (np.abs(got[:, 560:].astype(int) - 235).max(axis=2) > 40).mean()
        print(f"frame {k}: share of pixels drawn over, front {front:.4f}, side {side:.4f}")  # measured: 0.067 a
        assert (front > 0.045 * (k % 3) and side > 0.09) if k % 3 else (front < 0.001 and side == 0)  # person


def test_people_are_drawn_in_their_colours_with_their_ids(default_model_dir):
    """Two people side by side: each one's pixels in the colour of their identity (shaded), the nearer one hiding
    the farther where they overlap, and an id label above each."""
    model = load(default_model_dir)
    vertices, _ = _posed(model)
    faces = np.asarray(model.faces)
    frame = np.zeros((400, 600, 3), np.uint8)
    people = [Posed(0, vertices + [-0.5, 0.0, 3.0], 1.0, np.zeros(2)), Posed(3, vertices + [0.5, 0.0, 3.0], 1.0,
                                                                            np.zeros(2))]
    drawn = people_over_frame(frame, people, faces, 1.0, 300.0, np.array([300.0, 200.0]), labels=False)
    for person, half in zip(people, (drawn[:, :300], drawn[:, 300:])):
        assert _share_of_colour(half[half.max(axis=2) > 0], person.person_id) > 0.9
    assert person_colour(0) != person_colour(3)
    labelled = people_over_frame(frame, people, faces, 1.0, 300.0, np.array([300.0, 200.0]))
    assert (labelled != drawn).any()  # the ids above the heads
    front = [Posed(0, vertices + [0.0, 0.0, 3.0], 1.0, np.zeros(2)), Posed(1, vertices + [0.0, 0.0, 4.0], 1.0,
                                                                          np.zeros(2))]
    both = people_over_frame(frame, front, faces, 1.0, 300.0, np.array([300.0, 200.0]), labels=False)
    alone = people_over_frame(frame, front[:1], faces, 1.0, 300.0, np.array([300.0, 200.0]), labels=False)
    inside = alone.max(axis=2) > 0
    assert _share_of_colour(both[inside], 0) > 0.9  # the nearer one hides the one behind


def _share_of_colour(pixels: np.ndarray, person_id: int) -> float:
    """The share of ``pixels`` (N, 3) in the hue of ``person_id``'s colour (any shade of it)."""
    colour = np.asarray(person_colour(person_id), float)
    pixels = pixels.astype(float)
    cosine = pixels @ colour / (np.linalg.norm(pixels, axis=1) * np.linalg.norm(colour) + 1e-9)
    return float(np.mean(cosine > 0.995)) if len(pixels) > 1000 else 0.0
