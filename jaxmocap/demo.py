"""``jaxmocap demo``: the main job on the bundled sample clip; and renders of a body model for a person to check."""

from pathlib import Path

import cv2
import jax
import numpy as np

import smplx_jax
from jaxmocap.poses import example_pose
from jaxmocap.render import draw_mesh, label, view_points

DEMO_CLIP = Path(__file__).parent / "data" / "pose2sim_single_cam01.mp4"


def _view(vertices, faces, size, caption, **view):
    blank = np.full((size[1], size[0], 3), 255, np.uint8)
    return label(draw_mesh(blank, view_points(vertices, size, **view), faces), caption)


def body_model_sheets(model: smplx_jax.BodyModel) -> dict[str, np.ndarray]:
    """Named BGR images: ``body`` (rest and example pose, front and side), ``face`` and ``hand`` close-ups."""
    forward = jax.jit(smplx_jax.forward)
    faces = np.asarray(model.faces)
    rest = np.asarray(forward(model, smplx_jax.SMPLXParams.zeros(model.num_betas, model.num_expression)).vertices)
    posed = np.asarray(forward(model, example_pose(model.num_betas, model.num_expression)).vertices)
    head = rest[:, 1] > rest[:, 1].max() - 0.26
    hand = rest[:, 0] < rest[:, 0].min() + 0.2
    body = [[_view(v, faces, (480, 640), f"{name}, {side}", yaw_deg=yaw) for side, yaw in (("front", 0), ("side", 90))]
            for name, v in (("rest pose", rest), ("example pose", posed))]
    face = [_view(rest, faces, (450, 450), f"face, {yaw} deg", yaw_deg=yaw, focus=head) for yaw in (0, 35, 90)]
    face.append(_view(posed, faces, (450, 450), "jaw open, head turned", focus=head))
    palm = [_view(rest, faces, (600, 450), f"right hand, {name}", pitch_deg=pitch, focus=hand)
            for name, pitch in (("back", -80), ("palm", 80))]
    palm.append(_view(posed, faces, (600, 450), "fist", focus=hand))
    return {"body": np.concatenate([np.concatenate(row, axis=1) for row in body]),
            "face": np.concatenate(face, axis=1), "hand": np.concatenate(palm, axis=1)}


def render_body_model(model_path: Path, out_dir: Path) -> list[Path]:
    """PNG sheets of a body model file: rest and example pose front and side, face and hand close-ups."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, image in body_model_sheets(smplx_jax.load_model(model_path)).items():
        path = out_dir / f"body_model{'' if name == 'body' else '_' + name}.png"
        if not cv2.imwrite(str(path), image):
            raise PermissionError(f"cannot write {path}")
        written.append(path)
    return written


def demo(out_dir: Path, frankmocap_pkl: bool = False):
    """The main job on the bundled Pose2Sim clip, with both exports (and FrankMocap's pickles if asked)."""
    from jaxmocap.pipeline import RunConfig, run

    return run(RunConfig(DEMO_CLIP, exports=("bvh", "gltf"), frankmocap_pkl=frankmocap_pkl), out_dir)
