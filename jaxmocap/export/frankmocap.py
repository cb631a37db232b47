"""FrankMocap's per-frame prediction pickles (``--save_pred_pkl`` of its ``demo/demo_frankmocap.py``, demo type
``frank``) from a motion and the detector's boxes, for FrankMocap's own tools (``demo/demo_visualize_prediction.py``)
and the scripts written for them.

Layout as ``mocap_utils/demo_utils.py::save_pred_to_pkl`` writes it: ``<out>/mocap/<image stem>_prediction_result.pkl``
(``pickle.dump``, default protocol), an ``OrderedDict`` of ``demo_type`` "frank", ``smpl_type`` "smplx",
``image_path``, ``body_bbox_list`` [(x, y, w, h)], ``hand_bbox_list`` [{``left_hand``, ``right_hand``: (x, y, w, h)
or None}], ``save_mesh`` False and ``pred_output_list``: one dict per person with the keys of
``integration/copy_and_paste.py::integration_copy_paste`` (vertices left out, as FrankMocap does without
``--save_mesh``). Its conventions: ``pred_body_pose`` (1, 72) SMPL-style (global, 21 body joints, SMPL's two hand
joints, unused by SMPL-X, as zeros); hand poses (1, 45) relative to the mean hand (its SMPL-X layer has
``flat_hand_mean=False``); no translation: ``transl`` is folded into ``pred_camera``, the weak-perspective camera of
the body crop, ``pixel = (X s + t) 112 / bbox_scale_ratio + bbox_top_left + 112 / bbox_scale_ratio``
(``mocap_utils/coordconv.py``); each hand's camera likewise for its crop, ``((X + t) s) ...`` with X relative to
the hand's index1 joint. ``pred_body_joints_img`` holds SPIN's 49 joints; the 9 that FrankMocap regresses with its
own extra regressor file (LSP, MPII, H36M joints) are the nearest SMPL-X joints. We keep no body-only wrist, so
``*_orient_body`` hold the integrated wrist, as ``*_orient_hand`` do (None where the hand was not seen, as in
FrankMocap). Every person of a frame is in ``pred_output_list``, largest box first, as FrankMocap orders them.
"""

import functools
import io
import pickle
from collections import OrderedDict
from pathlib import Path

import jax
import numpy as np

import smplx_jax
from jaxmocap.motion import motion_params
from jaxmocap.regressors.crops import SIZE, body_windows, hand_windows
from smplx_jax import constants
from smplx_jax.atomic_files import atomic_write_bytes
from smplx_jax.rotations import rotmat_to_rotvec

_HALF = SIZE / 2
_SMPLX_FROM_SPIN_SMPL = list(range(22)) + [28, 43] + list(range(55, 76))  # FrankMocap's SMPLX wrapper, 45 joints
_SPIN_JOINT_MAP = [24, 12, 17, 19, 21, 16, 18, 20, 0, 2, 5, 8, 1, 4, 7, 25, 26, 27, 28, 29, 30, 31, 32, 33, 34,
                   8, 5, 45, 46, 4, 7, 21, 19, 17, 16, 18, 20, 47, 48, 49, 50, 51, 52, 53, 24, 26, 25, 28, 27]
# SPIN's extra joints (FrankMocap regresses them with a file of its own) as the nearest SMPL-X joints: hips, neck
# (LSP), pelvis (MPII), thorax (MPII), spine (H36M), jaw (H36M), head (H36M); the top of the head (LSP, 48) is the
# head joint extended from the neck by as much again.
_NECK, _HEAD = constants.JOINT_NAMES.index("neck"), constants.JOINT_NAMES.index("head")
_EXTRA_FROM_SMPLX = {45: 2, 46: 1, 47: _NECK, 48: -1, 49: 0, 50: 9, 51: 6, 52: 22, 53: _HEAD}
SPIN49_FROM_SMPLX = np.array([_SMPLX_FROM_SPIN_SMPL[j] if j < 45 else _EXTRA_FROM_SMPLX[j] for j in _SPIN_JOINT_MAP])
_HANDS = (("left", constants.LEFT_WRIST, 25, slice(25, 46)), ("right", constants.RIGHT_WRIST, 40, slice(46, 67)))


@jax.jit
@functools.partial(jax.vmap, in_axes=(None, 0))
def _joints_and_wrists(model, params):
    """The 127 joints (``transl`` included) and the wrists' global axis-angles (left, right) of each body."""
    wrists = smplx_jax.posed_skeleton(model, params).glob_rotmats[constants.LEFT_WRIST:constants.RIGHT_WRIST + 1]
    return smplx_jax.forward_joints(model, params), rotmat_to_rotvec(wrists)


def _xywh(box):
    return np.concatenate([box[..., :2], box[..., 2:] - box[..., :2]], axis=-1).astype(np.float32)


def _to_image(points, scale, trans, ratio, top_left, trans_first=False):
    """FrankMocap's ``convert_smpl_to_bbox`` then ``convert_bbox_to_oriIm``."""
    points = np.array(points, np.float32)
    if trans_first:
        points[:, :2] += trans
        points *= scale
    else:
        points *= scale
        points[:, :2] += trans
    points *= _HALF / ratio
    points[:, :2] += top_left + _HALF / ratio
    return points


def _person(model_arrays, motion, t, joints, wrists, body_box, hand_boxes, image_size):
    """The ``pred_output_list`` entry of frame ``t`` (``joints`` (127, 3) with ``transl``, ``wrists`` (2, 3) global
    axis-angles); ``model_arrays``: faces and mean hands of the body model."""
    scale, trans, transl = motion["camera_scale"][t], motion["camera_trans"][t], motion["transl"][t]
    window = body_windows(_xywh(body_box)[None], image_size)
    ratio, top_left = SIZE / float(window.size[0, 1]), window.origin[0]
    camera = np.array([scale * ratio / _HALF, *((scale * transl[:2] + trans - top_left) * ratio / _HALF - 1)],
                      np.float32)
    rest = joints - transl  # FrankMocap's layer has no translation
    body_pose = np.concatenate([motion["global_orient"][t], motion["body_pose"][t].ravel(), np.zeros(6)])
    out = {"faces": model_arrays["faces"], "bbox_scale_ratio": ratio, "bbox_top_left": np.asarray(top_left),
           "pred_camera": camera, "pred_body_pose": body_pose.astype(np.float32).reshape(1, 72),
           "pred_betas": np.asarray(motion["betas"][t], np.float32).reshape(1, -1)}
    spin = rest[np.maximum(SPIN49_FROM_SMPLX, 0)]
    spin[SPIN49_FROM_SMPLX < 0] = 2 * rest[_HEAD] - rest[_NECK]
    out["pred_body_joints_img"] = _to_image(spin, camera[0], camera[1:], ratio, top_left).astype(np.float32)
    pixels = scale * joints[:, :2] + trans
    for k, (side, wrist, index1, openpose) in enumerate(_HANDS):
        hand_joints = rest[np.asarray(constants.OPENPOSE67_FROM_SMPLX)[openpose]]
        out[f"pred_{side[0]}hand_joints_img"] = _to_image(hand_joints, camera[0], camera[1:], ratio, top_left)
        local = np.asarray(motion["body_pose"][t, wrist - 1], np.float32).reshape(1, 3)
        world = np.asarray(wrists[k], np.float32).reshape(1, 3)
        seen = bool(np.all(np.isfinite(hand_boxes[k])))
        out[f"{side}_hand_local_orient_body"], out[f"{side}_hand_global_orient_body"] = local, world
        out[f"{side}_hand_local_orient_hand"] = local if seen else None
        out[f"{side}_hand_global_orient_hand"] = world if seen else None
        relative = motion[f"{side}_hand_pose"][t].reshape(45) - model_arrays["hand_mean"][k]  # flat_hand_mean=False
        out[f"pred_{side}_hand_pose"] = relative.astype(np.float32).reshape(1, 45)
        camera_h = ratio_h = top_left_h = betas_h = None
        if seen:
            hand = hand_windows(_xywh(hand_boxes[k])[None], image_size)
            ratio_h, top_left_h = SIZE / float(hand.size[0, 1]), tuple(int(v) for v in hand.origin[0])
            origin = (pixels[index1] - top_left_h - _HALF / ratio_h) / scale
            camera_h = np.array([scale * ratio_h / _HALF, *origin], np.float32)
            betas_h = out["pred_betas"]
        out[f"pred_{side}_hand_betas"], out[f"{side}_hand_camera"] = betas_h, camera_h
        out[f"{side}_hand_bbox_scale_ratio"], out[f"{side}_hand_bbox_top_left"] = ratio_h, top_left_h
    return out


def write_frankmocap_pkls(out_dir, model: smplx_jax.BodyModel, people: dict, image_paths) -> list[Path]:
    """``out_dir/mocap/<stem>_prediction_result.pkl`` for every frame with a valid person (docs/formats.md),
    listing every such person, largest box first as FrankMocap orders them. ``people``: by identity, ``(motion,
    body_boxes (T, 4), hand_boxes (T, 2, 4))`` with boxes left, right as x0, y0, x1, y1 pixels, NaN where missing;
    ``image_paths``: the image each frame is (FrankMocap names a video's frames ``frames/<frame:05d>.jpg``). The
    pickles load under NumPy 1.x (FrankMocap's) as under NumPy 2 (`numpy1_pickle`)."""
    arrays = {"faces": np.asarray(model.faces), "hand_mean": np.asarray(model.hand_mean, np.float64)}
    frames = len(image_paths)
    entries = [[] for _ in range(frames)]  # per frame: (area, body box, hand boxes, person)
    for motion, body_boxes, hand_boxes in people.values():
        body_boxes, hand_boxes = np.asarray(body_boxes, np.float64), np.asarray(hand_boxes, np.float64)
        if len(motion["valid"]) != frames or body_boxes.shape != (frames, 4) or hand_boxes.shape != (frames, 2, 4):
            raise ValueError(f"expected {frames} frames, body_boxes ({frames}, 4) and hand_boxes ({frames}, 2, 4), got "
                             f"{len(motion['valid'])}, {body_boxes.shape} and {hand_boxes.shape}")
        rows = np.flatnonzero(np.asarray(motion["valid"], bool) & np.all(np.isfinite(body_boxes), axis=1))
        if not len(rows):
            continue
        params = motion_params(motion, model.num_expression, rows)
        joints, wrists = (np.asarray(a, np.float64) for a in _joints_and_wrists(model, params))
        image_size = tuple(int(v) for v in motion["image_size"])
        for n, t in enumerate(rows):
            person = _person(arrays, motion, t, joints[n], wrists[n], body_boxes[t], hand_boxes[t], image_size)
            hands = {side: _xywh(hand_boxes[t, k]) if np.all(np.isfinite(hand_boxes[t, k])) else None
                     for k, side in enumerate(("left_hand", "right_hand"))}
            area = np.prod(body_boxes[t, 2:] - body_boxes[t, :2])
            entries[t].append((area, _xywh(body_boxes[t]), hands, person))
    written = []
    for t, found in enumerate(entries):
        if not found:
            continue
        found.sort(key=lambda entry: -entry[0])
        image_path = Path(image_paths[t]).absolute()
        data = OrderedDict(demo_type="frank", smpl_type="smplx", image_path=str(image_path),
                           body_bbox_list=[e[1] for e in found], hand_bbox_list=[e[2] for e in found],
                           save_mesh=False, pred_output_list=[e[3] for e in found])
        path = Path(out_dir) / "mocap" / f"{image_path.stem}_prediction_result.pkl"
        written.append(atomic_write_bytes(path, numpy1_pickle(data)))
    return written


class _Numpy1Pickler(pickle._Pickler):
    """Python's pickler naming NumPy 2's ``numpy._core`` functions by their NumPy 1.x home ``numpy.core`` (which
    NumPy 2 still serves), so that either loads the file."""

    def save_global(self, obj, name=None):
        module = getattr(obj, "__module__", None) or ""
        if module == "numpy._core" or module.startswith("numpy._core."):
            qualified = f"numpy.core{module[len('numpy._core'):]}\n{name or obj.__qualname__}\n"
            self.write(pickle.GLOBAL + qualified.encode())
            self.memoize(obj)
            return
        super().save_global(obj, name)


def numpy1_pickle(obj) -> bytes:
    """``pickle.dumps(obj)`` (protocol 2) that NumPy 1.x unpickles too: arrays and scalars reconstructed through
    ``numpy.core`` rather than NumPy 2's ``numpy._core``."""
    buffer = io.BytesIO()
    _Numpy1Pickler(buffer, protocol=2).dump(obj)
    return buffer.getvalue()
