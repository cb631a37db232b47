"""Blender's own importers on the exports: each ``.bvh`` through ``io_anim_bvh`` and each ``.glb``/``.gltf``
through ``io_scene_gltf2``, in a fresh empty scene of Blender as a Python module (``bpy``), with what the
importers print captured. Per file it reports the armature's bones, the bones the importer found of zero length
(and lengthened: Blender's BVH importer prints ``zero length node found`` / ``zero length bone found``), the
shortest bone, the animation's frames, where the body stands at the first frame (``lowest_m``: Blender's z, up, of
the lowest evaluated mesh vertex of a glTF, of the lowest bone head or tail of a BVH; an export in the world frame
stands on the floor z = 0), and any other warning or error lines; it exits 1 unless every file imports with no
zero-length bone, warning or error.

``bpy`` is large (~400 MB) and needs its own Python version (bpy 4.x and 5.0: Python 3.11), so it lives in a
separate virtual environment, not in the project's:

    python3.11 -m venv /tmp/bpyenv && /tmp/bpyenv/bin/pip install bpy
    /tmp/bpyenv/bin/python bench/checks/blender_check.py out/motion.bvh out/motion.glb
"""

import contextlib
import json
import os
import re
import sys
import tempfile

import bpy  # first: it puts Blender's own modules (addon_utils) on the path

# isort: split
import addon_utils

_NOISE = re.compile(r"zero length|warn|error|fail|traceback|exception", re.IGNORECASE)


@contextlib.contextmanager
def _captured(lines: list):
    """Collects what is written to the process's stdout and stderr (Python's and Blender's C code's alike)."""
    sys.stdout.flush(), sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with tempfile.TemporaryFile("w+") as sink:
        os.dup2(sink.fileno(), 1), os.dup2(sink.fileno(), 2)
        try:
            yield
        finally:
            sys.stdout.flush(), sys.stderr.flush()
            os.dup2(saved[0], 1), os.dup2(saved[1], 2)
            os.close(saved[0]), os.close(saved[1])
            sink.seek(0)
            lines.extend(line.rstrip() for line in sink if line.strip())


def check(path: str) -> dict:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    for addon in ("io_anim_bvh", "io_scene_gltf2"):
        addon_utils.enable(addon, default_set=True)
    output, error = [], None
    with _captured(output):
        try:
            if path.lower().endswith(".bvh"):
                result = bpy.ops.import_anim.bvh(filepath=path, update_scene_fps=True, update_scene_duration=True)
            else:
                result = bpy.ops.import_scene.gltf(filepath=path)
        except Exception as exc:  # noqa: BLE001 - reported, not raised
            result, error = set(), f"{type(exc).__name__}: {exc}"
    armatures = [o for o in bpy.data.objects if o.type == "ARMATURE"]
    bones = [b for a in armatures for b in a.data.bones]
    actions = list(bpy.data.actions)
    zero = [line.split(":", 1)[-1].strip() for line in output if "zero length" in line]
    if actions:
        bpy.context.scene.frame_set(round(actions[0].frame_range[0]))
    return {
        "file": path, "blender": bpy.app.version_string, "result": sorted(result),
        "armatures": len(armatures), "bones": len(bones), "zero_length_bones": zero,
        "shortest_bone_m": round(min((b.length for b in bones), default=0.0), 5),
        "shortest_bone": min(bones, key=lambda b: b.length).name if bones else None,
        "meshes": {o.name: len(o.data.vertices) for o in bpy.data.objects if o.type == "MESH"},  # glTF: + bone shape
        "frames": [round(v) for v in actions[0].frame_range] if actions else None,
        "lowest_m": _lowest(armatures),
        "warnings": [line for line in output if _NOISE.search(line) and "zero length" not in line],
        "error": error,
    }


def _lowest(armatures) -> float | None:
    """Blender's z of the lowest point at the scene's frame: of the evaluated (skinned) meshes' vertices where there
    are meshes, else of the armatures' posed bones' heads and tails."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    meshes = [o.evaluated_get(depsgraph) for o in bpy.data.objects  # not the glTF importer's bone-shape spheres
              if o.type == "MESH" and len(o.data.vertices) > 100]
    if meshes:
        return round(min(min((o.matrix_world @ v.co).z for v in o.to_mesh().vertices) for o in meshes), 4)
    points = [(a.matrix_world @ p).z for a in armatures for b in a.pose.bones for p in (b.head, b.tail)]
    return round(min(points), 4) if points else None


def main(paths) -> int:
    if not paths:
        print(__doc__.strip().splitlines()[-1].strip(), file=sys.stderr)
        return 2
    clean = True
    for path in paths:
        report = check(os.path.abspath(path))
        print(json.dumps(report))
        clean &= (report["result"] == ["FINISHED"] and report["bones"] > 0 and not report["zero_length_bones"]
                  and not report["warnings"] and report["error"] is None)
    return 0 if clean else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
