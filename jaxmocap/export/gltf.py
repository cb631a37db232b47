"""glTF 2.0 export (binary ``.glb``, or ``.gltf`` JSON): the body mesh of the motion's mean shape, skinned to the
55-joint skeleton (four strongest joints per vertex), with one animation; glTF viewers in browsers and Blender
play it. `write_meshes` writes any skinned meshes so (the hands: `jaxmocap.export.hands_gltf`).

Pose-corrective blend shapes are not exported (glTF skinning cannot express them); for the default body model
they are zero, so the file reproduces the model exactly.
"""

import base64
import json
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import smplx_jax
from jaxmocap.export.animation import Animation
from smplx_jax.atomic_files import atomic_write_bytes, atomic_write_text
from smplx_jax.geometry import vertex_normals
from smplx_jax.rotations import rotmat_to_quat

FLOAT, USHORT, UINT = 5126, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
_TYPES = {1: "SCALAR", 3: "VEC3", 4: "VEC4", 16: "MAT4"}


def rest_mesh(model: smplx_jax.BodyModel, betas: np.ndarray) -> np.ndarray:
    """(V, 3) rest-pose vertices of a shape."""
    offsets = betas @ np.asarray(model.shapedirs_cm)[: len(betas)]
    return (np.asarray(model.template_cm, np.float64) + offsets.reshape(3, -1)).T


def top_weights(weights: np.ndarray, count: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """The ``count`` strongest joints of each vertex and their float32 weights, renormalised to sum to 1; a slot
    of zero weight names joint 0, as glTF asks (validators warn of unused slots naming other joints)."""
    joints = np.argsort(-weights, axis=1, kind="stable")[:, :count]
    top = np.take_along_axis(weights, joints, axis=1)
    top = (top / top.sum(axis=1, keepdims=True)).astype(np.float32)
    return np.where(top > 0, joints, 0), top


def _quaternions_xyzw(rotmats: np.ndarray) -> np.ndarray:
    """(T, 4) glTF quaternions, signs chosen so that consecutive frames interpolate the short way."""
    quat = np.asarray(rotmat_to_quat(rotmats), np.float64)
    for t in range(1, len(quat)):
        if quat[t] @ quat[t - 1] < 0:
            quat[t] = -quat[t]
    return quat[:, [1, 2, 3, 0]]


class _Buffer:
    """Accumulates binary data and the glTF bufferViews/accessors that describe it."""

    def __init__(self):
        self.chunks, self.size, self.views, self.accessors = [], 0, [], []

    def add(self, array: np.ndarray, component: int, target=None, bounds=False) -> int:
        data = np.ascontiguousarray(array).tobytes()
        view = {"buffer": 0, "byteOffset": self.size, "byteLength": len(data)}
        if target:
            view["target"] = target
        self.views.append(view)
        self.chunks.append(data + b"\0" * (-len(data) % 4))
        self.size += len(data) + (-len(data) % 4)
        width = 1 if array.ndim == 1 else int(np.prod(array.shape[1:]))
        accessor = {"bufferView": len(self.views) - 1, "componentType": component, "count": len(array),
                    "type": _TYPES[width]}
        if bounds:
            flat = array.reshape(len(array), -1)
            accessor["min"], accessor["max"] = flat.min(axis=0).tolist(), flat.max(axis=0).tolist()
        self.accessors.append(accessor)
        return len(self.accessors) - 1


@dataclass(frozen=True)
class SkinnedMesh:
    """A mesh in its rest pose, skinned to the skeleton of an animation."""

    name: str
    vertices: np.ndarray  # (V, 3) rest pose, metres
    faces: np.ndarray  # (F, 3)
    weights: np.ndarray  # (V, J) skinning weights on the animation's joints
    anim: Animation


def body_mesh(model: smplx_jax.BodyModel, anim: Animation) -> SkinnedMesh:
    """The body of the animation's mean shape."""
    return SkinnedMesh("body", rest_mesh(model, anim.betas), np.asarray(model.faces),
                       np.asarray(model.weights_t, np.float64).T, anim)


def gltf_document(meshes: Sequence[SkinnedMesh]) -> tuple[dict, bytes]:
    """The glTF JSON document and its binary buffer: one scene with each mesh and its skeleton, and one animation
    of them all (the animations share their frames and frame rate)."""
    buf = _Buffer()
    nodes, scene, mesh_docs, skins, roots = [], [], [], [], []
    for k, mesh in enumerate(meshes):
        anim, num_joints = mesh.anim, len(mesh.anim.parents)
        joints, weights = top_weights(mesh.weights)
        attributes = {
            "POSITION": buf.add(mesh.vertices.astype(np.float32), FLOAT, ARRAY_BUFFER, bounds=True),
            "NORMAL": buf.add(vertex_normals(mesh.vertices, mesh.faces).astype(np.float32), FLOAT, ARRAY_BUFFER),
            "JOINTS_0": buf.add(joints.astype(np.uint16), USHORT, ARRAY_BUFFER),
            "WEIGHTS_0": buf.add(weights, FLOAT, ARRAY_BUFFER),
        }
        indices = buf.add(mesh.faces.reshape(-1).astype(np.uint32), UINT, ELEMENT_ARRAY_BUFFER, bounds=True)
        inverse_bind = np.tile(np.eye(4), (num_joints, 1, 1))
        inverse_bind[:, :3, 3] = -anim.rest_joints
        ibm = buf.add(inverse_bind.transpose(0, 2, 1).reshape(num_joints, 16).astype(np.float32), FLOAT)

        root = len(nodes)
        for j in range(num_joints):
            offset = anim.rest_joints[j] - (anim.rest_joints[anim.parents[j]] if j else 0.0)
            node = {"name": anim.names[j], "translation": offset.tolist()}
            children = [root + c for c in range(num_joints) if anim.parents[c] == j]
            if children:
                node["children"] = children
            nodes.append(node)
        nodes.append({"name": mesh.name, "mesh": k, "skin": k})
        scene += [root, len(nodes) - 1]
        roots.append(root)
        mesh_docs.append({"name": mesh.name, "primitives": [
            {"attributes": attributes, "indices": indices, "material": 0}]})
        skins.append({"joints": list(range(root, root + num_joints)), "inverseBindMatrices": ibm, "skeleton": root})

    first = meshes[0].anim
    times = buf.add((np.arange(len(first.local_rotmats)) / first.fps).astype(np.float32), FLOAT, bounds=True)
    samplers, channels = [], []
    for mesh, root in zip(meshes, roots):
        for j in range(len(mesh.anim.parents)):
            rotations = buf.add(_quaternions_xyzw(mesh.anim.local_rotmats[:, j]).astype(np.float32), FLOAT)
            channels.append({"sampler": len(samplers), "target": {"node": root + j, "path": "rotation"}})
            samplers.append({"input": times, "output": rotations, "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers), "target": {"node": root, "path": "translation"}})
        samplers.append({"input": times, "output": buf.add(mesh.anim.root_positions.astype(np.float32), FLOAT),
                         "interpolation": "LINEAR"})

    document = {
        "asset": {"version": "2.0", "generator": "jaxmocap"},
        "scene": 0,
        "scenes": [{"nodes": scene}],
        "nodes": nodes,
        "meshes": mesh_docs,
        "materials": [{"name": "skin", "pbrMetallicRoughness": {
            "baseColorFactor": [0.85, 0.68, 0.58, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.8}}],
        "skins": skins,
        "animations": [{"name": "motion", "samplers": samplers, "channels": channels}],
        "accessors": buf.accessors,
        "bufferViews": buf.views,
        "buffers": [{"byteLength": buf.size}],
    }
    return document, b"".join(buf.chunks)


def write_meshes(path, meshes: Sequence[SkinnedMesh]) -> Path:
    """Write glTF atomically: binary (``.glb``) unless the name ends in ``.gltf`` (JSON, buffer embedded)."""
    document, binary = gltf_document(meshes)
    if Path(path).suffix.lower() == ".gltf":
        document["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
        return atomic_write_text(path, json.dumps(document, separators=(",", ":")))
    text = json.dumps(document, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    length = 12 + 8 + len(text) + 8 + len(binary)
    header = struct.pack("<4sII", b"glTF", 2, length)
    chunks = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(binary), b"BIN\0") + binary
    return atomic_write_bytes(path, header + chunks)


def write_gltf(path, model: smplx_jax.BodyModel, anim: Animation) -> Path:
    """Write the body of a motion's animation as glTF (`write_meshes`)."""
    return write_meshes(path, [body_mesh(model, anim)])
