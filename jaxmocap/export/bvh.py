"""BVH export: the 55-joint SMPL-X skeleton and its animation, in metres, y up (Blender's importer reads it). Each
leaf joint's End Site reaches the tip its bone points to (toes, finger tips, lower lip, eye front; see
`jaxmocap.export.animation.LEAF_TIPS`), so no bone has zero length."""

from pathlib import Path

import numpy as np

from jaxmocap.export.animation import Animation
from smplx_jax.atomic_files import atomic_write_text


def zyx_euler_degrees(rotmats: np.ndarray) -> np.ndarray:
    """(..., 3) angles (z, y, x) in degrees with ``R = Rz(z) @ Ry(y) @ Rx(x)``, BVH's ``Zrotation Yrotation
    Xrotation`` channel order."""
    sy = -np.clip(rotmats[..., 2, 0], -1.0, 1.0)
    y = np.arcsin(sy)
    locked = np.abs(sy) > 1 - 1e-9  # gimbal lock: put all of the remaining turn into z
    z = np.where(locked, np.arctan2(-rotmats[..., 0, 1], rotmats[..., 1, 1]),
                 np.arctan2(rotmats[..., 1, 0], rotmats[..., 0, 0]))
    x = np.where(locked, 0.0, np.arctan2(rotmats[..., 2, 1], rotmats[..., 2, 2]))
    return np.degrees(np.stack([z, y, x], axis=-1))


def _hierarchy(anim: Animation) -> tuple[list[str], list[int]]:
    """BVH hierarchy lines and the joints in the order their channels appear (depth first)."""
    children = {j: [c for c in range(len(anim.parents)) if anim.parents[c] == j] for j in range(len(anim.parents))}
    lines, order = [], []

    def visit(j, depth):
        pad = "  " * depth
        offset = anim.rest_joints[j] - (anim.rest_joints[anim.parents[j]] if j else anim.rest_joints[j])
        lines.append(f"{pad}{'ROOT' if j == 0 else 'JOINT'} {anim.names[j]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {offset[0]:.6f} {offset[1]:.6f} {offset[2]:.6f}")
        channels = "6 Xposition Yposition Zposition" if j == 0 else "3"
        lines.append(f"{pad}  CHANNELS {channels} Zrotation Yrotation Xrotation")
        order.append(j)
        for c in children[j]:
            visit(c, depth + 1)
        if not children[j]:
            end = anim.end_sites[j]
            end_site = ["End Site", "{", f"  OFFSET {end[0]:.6f} {end[1]:.6f} {end[2]:.6f}", "}"]
            lines.extend(f"{pad}  {line}" for line in end_site)
        lines.append(f"{pad}}}")

    visit(0, 0)
    return lines, order


def write_bvh(path, anim: Animation) -> Path:
    """Write the animation as BVH (atomically); the root carries the world position of the pelvis."""
    lines, order = _hierarchy(anim)
    angles = zyx_euler_degrees(anim.local_rotmats[:, order])  # (T, 55, 3)
    frames = np.concatenate([anim.root_positions, angles.reshape(len(angles), -1)], axis=1)
    text = "\n".join(["HIERARCHY", *lines, "MOTION", f"Frames: {len(frames)}", f"Frame Time: {1.0 / anim.fps:.8f}"])
    body = "\n".join(" ".join(f"{v:.6f}" for v in row) for row in frames)
    return atomic_write_text(path, text + "\n" + body + "\n")
