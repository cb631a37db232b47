"""Reading a ``.glb`` back: its JSON and binary chunks, accessors (checked against their views), and the vertices
of a skinned mesh node as glTF's skinning puts them at a frame of the animation."""

import json
import struct

import numpy as np

from smplx_jax.rotations import quat_to_rotmat


def read_glb(path):
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_len, json_type = struct.unpack_from("<I4s", data, 12)
    assert json_type == b"JSON" and json_len % 4 == 0
    doc = json.loads(data[20:20 + json_len])
    bin_len, bin_type = struct.unpack_from("<I4s", data, 20 + json_len)
    assert bin_type == b"BIN\0" and bin_len == doc["buffers"][0]["byteLength"]
    return doc, data[28 + json_len: 28 + json_len + bin_len]


def accessor(doc, binary, index):
    """Checks an accessor against its bufferView and the buffer, and returns its data."""
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype = {5126: np.float32, 5123: np.uint16, 5125: np.uint32}[acc["componentType"]]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc["type"]]
    assert view["byteOffset"] % 4 == 0 and view["byteOffset"] + view["byteLength"] <= len(binary)
    assert view["byteLength"] == acc["count"] * width * np.dtype(dtype).itemsize
    array = np.frombuffer(binary, dtype, acc["count"] * width, view["byteOffset"]).reshape(acc["count"], width)
    if "min" in acc:
        np.testing.assert_allclose(acc["min"], array.min(axis=0), rtol=1e-6)
        np.testing.assert_allclose(acc["max"], array.max(axis=0), rtol=1e-6)
    return array


def sampled(doc, binary) -> dict:
    """``(node, path) -> (T, k)`` values of the first animation's channels, float64."""
    animation = doc["animations"][0]
    values = {}
    for channel in animation["channels"]:
        sampler = animation["samplers"][channel["sampler"]]
        values[(channel["target"]["node"], channel["target"]["path"])] = \
            accessor(doc, binary, sampler["output"]).astype(np.float64)
    return values


def skinned_vertices(doc, binary, node: int, frame: int) -> np.ndarray:
    """(V, 3) world positions of the vertices of the skinned mesh at ``doc["nodes"][node]`` at ``frame``."""
    skin = doc["skins"][doc["nodes"][node]["skin"]]
    attributes = doc["meshes"][doc["nodes"][node]["mesh"]]["primitives"][0]["attributes"]
    positions = accessor(doc, binary, attributes["POSITION"]).astype(np.float64)
    joints = accessor(doc, binary, attributes["JOINTS_0"]).astype(int)
    weights = accessor(doc, binary, attributes["WEIGHTS_0"]).astype(np.float64)
    ibm = accessor(doc, binary, skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
    values = sampled(doc, binary)
    parent = {c: p for p, n in enumerate(doc["nodes"]) for c in n.get("children", [])}

    def world(n):
        local = np.eye(4)
        quat = values[(n, "rotation")][frame] if (n, "rotation") in values else doc["nodes"][n].get("rotation")
        if quat is not None:
            local[:3, :3] = np.asarray(quat_to_rotmat(np.asarray(quat)[[3, 0, 1, 2]]))
        local[:3, 3] = values[(n, "translation")][frame] if (n, "translation") in values else \
            doc["nodes"][n].get("translation", 0.0)
        return local if n not in parent else world(parent[n]) @ local

    mats = np.array([world(j) for j in skin["joints"]]) @ ibm
    blended = np.einsum("vk,vkij->vij", weights, mats[joints])
    return np.einsum("vij,vj->vi", blended[:, :3, :3], positions) + blended[:, :3, 3]
