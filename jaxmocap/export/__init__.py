"""Animation files from a motion: BVH (skeleton) and binary glTF 2.0 (skinned mesh), y up, metres; the hands of a
hands file as glTF."""

from jaxmocap.export.animation import Animation, animation, global_transforms
from jaxmocap.export.bvh import write_bvh
from jaxmocap.export.files import export_motion
from jaxmocap.export.gltf import write_gltf
from jaxmocap.export.hands_gltf import write_hands_gltf

__all__ = ["Animation", "animation", "export_motion", "global_transforms", "write_bvh", "write_gltf",
           "write_hands_gltf"]
