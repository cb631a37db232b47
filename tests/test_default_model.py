"""The generated license-free default body model: file layout, a sound closed surface, anatomy, rig,
shape space, and that the PyTorch ``smplx`` package runs on it."""

import numpy as np
import pytest

from smplx_jax import constants, default_model
from smplx_jax.default_model import build_default_model, default_model_path, generator_id, write_default_model
from smplx_jax.geometry import face_normals, vertex_normals

PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15, 20, 25, 26, 20, 28,
           29, 20, 31, 32, 20, 34, 35, 20, 37, 38, 21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50, 21, 52, 53]
SHAPES = {
    "v_template": ((10475, 3), np.float64), "shapedirs": ((10475, 3, 400), np.float64),
    "posedirs": ((10475, 3, 486), np.float64), "J_regressor": ((55, 10475), np.float64),
    "weights": ((10475, 55), np.float64), "kintree_table": ((2, 55), np.int64), "f": ((None, 3), np.int64),
    "hands_componentsl": ((45, 45), np.float64), "hands_componentsr": ((45, 45), np.float64),
    "hands_meanl": ((45,), np.float64), "hands_meanr": ((45,), np.float64), "lmk_faces_idx": ((51,), np.int64),
    "lmk_bary_coords": ((51, 3), np.float64),
}
VID = dict(zip(constants.VERTEX_JOINT_NAMES, constants.VERTEX_JOINT_IDS))


@pytest.fixture(scope="module")
def m():
    return build_default_model()


@pytest.fixture(scope="module")
def joints(m):
    return m["J_regressor"] @ m["v_template"]


def test_keys_shapes_dtypes(m):
    assert set(SHAPES) <= set(m) and set(m) - set(SHAPES) <= {"dynamic_lmk_faces_idx", "dynamic_lmk_bary_coords"}
    for key, (shape, dtype) in SHAPES.items():
        assert m[key].dtype == dtype, key
        assert all(a == b for a, b in zip(m[key].shape, shape) if b is not None) and m[key].ndim == len(shape), key
        assert np.all(np.isfinite(m[key])), key
    parents = m["kintree_table"][0].copy()
    assert parents[0] in (-1, 4294967295)
    parents[0] = -1
    assert parents.tolist() == PARENTS
    assert m["kintree_table"][1].tolist() == list(range(55))
    assert np.allclose(m["lmk_bary_coords"].sum(1), 1) and m["lmk_bary_coords"].min() >= 0


def test_weights_and_regressor(m):
    w, R = m["weights"], m["J_regressor"]
    assert w.min() >= 0 and np.allclose(w.sum(1), 1)
    assert (w > 0).sum(1).max() <= 6
    assert np.allclose(R.sum(1), 1)
    assert (R != 0).sum(1).max() <= 40 and (R != 0).sum(1).min() >= 4
    # every body and finger joint moves some skin; the eyes may move none
    used = np.where(w.sum(0) > 1.0)[0]
    assert set(range(23)) | set(range(25, 55)) <= set(used)


def _edges(f):
    return np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])


def test_closed_oriented_manifold(m):
    v, f = m["v_template"], m["f"]
    assert len(np.unique(f)) == len(v)  # no unused vertex
    directed = _edges(f)
    key = directed[:, 0] * len(v) + directed[:, 1]
    assert len(np.unique(key)) == len(key), "a directed edge occurs twice (non-manifold or flipped face)"
    assert np.isin(directed[:, 1] * len(v) + directed[:, 0], key).all(), "open boundary or inconsistent winding"
    n_edges = len(key) // 2
    assert len(v) - n_edges + len(f) == 2  # a sphere
    tri = v[f]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.linalg.norm(cross, axis=1).min() > 1e-9, "degenerate triangle"
    volume = np.einsum("ij,ij->i", tri[:, 0], cross).sum() / 6
    assert 0.05 < volume < 0.10  # outward normals; an adult is about 65 litres


def test_vertex_normals(m):
    """A regular tetrahedron's vertex normals point from its centre through the vertices; an unused vertex's is 0.
    On the model, the normals (that the generator and the glTF export share) are unit and point outwards."""
    v = np.array([[1.0, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1], [5, 5, 5]])
    f = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])
    np.testing.assert_allclose(np.linalg.norm(face_normals(v, f), axis=1), 2 * np.sqrt(3) * 4 / 2)  # 2 x area
    np.testing.assert_allclose(vertex_normals(v, f), np.vstack([v[:4] / np.sqrt(3), np.zeros(3)]), atol=1e-12)
    normals = vertex_normals(m["v_template"], m["f"])
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1, atol=1e-6)  # eye corners: ~1e-6 m² around
    along = np.einsum("fi,fi->f", face_normals(m["v_template"], m["f"]), normals[m["f"]].sum(axis=1))
    assert np.mean(along > 0) > 0.99 and normals[np.argmax(m["v_template"][:, 1]), 1] > 0.9  # crown: up
    assert generator_id().startswith("v1-")  # hashes geometry.py too


def _inside(points, v, f):
    """Winding numbers of ``points`` with respect to the closed mesh."""
    out = []
    for p in points:
        a, b, c = (v[f[:, k]] - p for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        det = np.einsum("ij,ij->i", a, np.cross(b, c))
        den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la \
            + np.einsum("ij,ij->i", c, a) * lb
        out.append(np.arctan2(det, den).sum() / (2 * np.pi))
    return np.array(out)


def test_proportions_and_joints(m, joints):
    v = m["v_template"]
    height = v[:, 1].max() - v[:, 1].min()
    assert 1.60 < height < 1.80
    assert abs(v[:, 1].min() + 1.30) < 0.03 and abs(v[:, 1].max() - 0.38) < 0.03
    span = v[:, 0].max() - v[:, 0].min()
    assert abs(span / height - 1.0) < 0.06
    assert np.abs(joints[0] - [0, -0.35, 0.01]).max() < 0.03
    # left joints at +x, mirrored right joints
    left = [1, 4, 7, 10, 13, 16, 18, 20] + list(range(25, 40))
    right = [2, 5, 8, 11, 14, 17, 19, 21] + list(range(40, 55))
    assert (joints[left, 0] > 0.03).all()
    assert np.allclose(joints[left] * [-1, 1, 1], joints[right], atol=1e-6)
    # every joint but the eyes lies inside the body; the knee halfway down the leg, elbows halfway along arms
    wn = _inside(np.delete(joints, [23, 24], 0), v, m["f"])
    assert np.all(np.abs(wn - 1) < 1e-6), np.where(np.abs(wn - 1) > 1e-6)
    hip, knee, ankle = joints[1], joints[4], joints[7]
    assert 0.4 < (hip[1] - knee[1]) / (hip[1] - ankle[1]) < 0.6
    assert joints[16, 0] < joints[18, 0] < joints[20, 0] < joints[25, 0] < joints[26, 0] < joints[27, 0]
    assert joints[15, 1] < joints[23, 1] and joints[23, 2] > joints[15, 2] + 0.05  # eyes above/in front of head
    assert joints[15, 1] - 0.03 < joints[22, 1] < joints[23, 1]  # jaw hinge below the eyes, above the neck
    assert np.all(np.abs(v[[VID["left_ear"], VID["right_ear"]], 1] - joints[22, 1]) < 0.06)


def test_vertex_joints_at_their_places(m, joints):
    v, w = m["v_template"], m["weights"]
    dom = np.argmax(w, 1)
    head = v[:, 1] > 0.16
    nose = v[VID["nose"]]
    assert abs(nose[0]) < 0.005 and nose[2] >= v[head, 2].max() - 1e-3
    for s, eye, ear, jeye in ((1, "left_eye_vertex", "left_ear", 23), (-1, "right_eye_vertex", "right_ear", 24)):
        p = v[VID[eye]]
        assert s * p[0] > 0.02 and np.linalg.norm(p - joints[jeye]) < 0.025 and p[2] > joints[jeye, 2]
        assert abs(p[1] - joints[jeye, 1]) < 0.01
        q = v[VID[ear]]
        assert s * q[0] > 0.07 and abs(q[2] - joints[15, 2]) < 0.05
    for s, side in ((1, "left"), (-1, "right")):
        half = s * v[:, 0] > 0
        foot = half & (v[:, 1] < -1.2)
        heel, big, small = v[VID[f"{side}_heel"]], v[VID[f"{side}_big_toe"]], v[VID[f"{side}_small_toe"]]
        assert heel[2] <= v[foot, 2].min() + 0.004
        assert big[2] > 0.12 and small[2] > 0.10 and big[1] < -1.25 and small[1] < -1.25
        assert s * big[0] < s * small[0] - 0.03  # big toe medial
        assert big[2] >= v[foot, 2].max() - 0.015
        base = 25 if s > 0 else 40
        for n, finger in enumerate(("index", "middle", "pinky", "ring", "thumb")):
            tip = VID[f"{side}_{finger}_tip"]
            last = base + 3 * n + 2
            ids = np.where(dom == last)[0]
            assert tip in ids
            direction = v[ids].mean(0) - joints[last] if finger == "thumb" else np.array([s, 0, 0])
            proj = v[ids] @ direction
            assert proj.max() - v[tip] @ direction < 1e-3 * np.linalg.norm(direction)


def test_no_weight_leakage(m):
    v, w = m["v_template"], m["weights"]
    left_leg, right_leg = [1, 4, 7, 10], [2, 5, 8, 11]
    assert w[v[:, 0] < -0.02][:, left_leg].max() == 0
    assert w[v[:, 0] > 0.02][:, right_leg].max() == 0
    hand = {"index": 25, "middle": 28, "pinky": 31, "ring": 34, "thumb": 37}
    for name, j in hand.items():  # a fingertip segment has no weight of another finger
        tip_vertices = np.argmax(w, 1) == j + 2
        others = [k for k in range(25, 40) if not j <= k < j + 3]
        assert w[tip_vertices][:, others].max() == 0, name


def test_hand_pca(m):
    for side in "lr":
        c = m[f"hands_components{side}"]
        assert np.allclose(c @ c.T, np.eye(45), atol=1e-8)
    mirror = np.tile([1, -1, -1], 15)
    assert np.allclose(m["hands_componentsl"], m["hands_componentsr"] * mirror)
    assert np.allclose(m["hands_meanl"], m["hands_meanr"] * mirror)
    # right hand: flexion is about +z; the mean is slightly curled, the first component closes the hand
    flex = m["hands_meanr"].reshape(15, 3)[:12, 2]
    assert 0.1 < flex.mean() < 1.0
    assert m["hands_componentsr"][0].reshape(15, 3)[:12, 2].min() > 0


def test_shape_and_expression_space(m):
    sd = m["shapedirs"]
    assert np.all(sd[:, :, 11:300] == 0) and np.all(sd[:, :, 310:] == 0)
    norms = np.linalg.norm(sd[:, :, :10].reshape(-1, 10), axis=0)
    assert (norms > 0.01).all() and np.all(np.diff(norms) <= 1e-9)  # ordered by variance
    assert (np.linalg.norm(sd[:, :, 300:310].reshape(-1, 10), axis=0) > 1e-3).all()
    v, f = m["v_template"], m["f"]
    edges = _edges(f)
    e0 = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    n0 = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    for k in range(10):
        for b in (-3.0, 3.0):
            vs = v + b * sd[:, :, k]
            height = vs[:, 1].max() - vs[:, 1].min()
            assert 1.45 < height < 1.95, (k, b, height)
            ratio = (np.linalg.norm(vs[edges[:, 0]] - vs[edges[:, 1]], axis=1) / e0)[e0 > 0.002]
            assert 0.3 < ratio.min() and ratio.max() < 3.0, (k, b, ratio.min(), ratio.max())
            n = np.cross(vs[f[:, 1]] - vs[f[:, 0]], vs[f[:, 2]] - vs[f[:, 0]])
            assert np.mean(np.einsum("ij,ij->i", n, n0) < 0) < 0.002, (k, b)  # hardly any face flips
    # expressions only move the face
    moved = np.linalg.norm(sd[:, :, 300:310], axis=1).max(1) > 1e-5
    assert v[moved, 1].min() > 0.13


def test_face_contour_table(m):
    idx, bary = m["dynamic_lmk_faces_idx"], m["dynamic_lmk_bary_coords"]
    assert idx.shape == (79, 17) and idx.dtype == np.int64 and bary.shape == (79, 17, 3)
    assert idx.min() >= 0 and idx.max() < len(m["f"]) and np.allclose(bary.sum(-1), 1)
    v, f = m["v_template"], m["f"]
    pts = np.einsum("rlk,rlkj->rlj", bary, v[f[idx]])
    sym = [k for k in range(17) if k != 8]
    assert np.allclose(pts[0, sym, 0], -pts[0, sym[::-1], 0], atol=5e-3)  # frontal contour is symmetric
    assert abs(pts[0, 8, 0]) < 0.025
    assert pts[0, 8, 1] < pts[0, [0, 16], 1].min() - 0.04  # chin below the ends of the jaw line


def test_landmarks_on_face(m):
    v, f = m["v_template"], m["f"]
    lm = np.einsum("lk,lkj->lj", m["lmk_bary_coords"], v[f[m["lmk_faces_idx"]]])
    head = (m["J_regressor"] @ v)[15]
    assert (lm[:, 2] > head[2] + 0.05).all() and (lm[:, 1] > 0.15).all() and (lm[:, 1] < 0.33).all()
    brows, nose, eyes, mouth = lm[:10], lm[10:19], lm[19:31], lm[31:]
    assert brows[:, 1].min() > eyes[:, 1].max() > nose[:, 1].min() > mouth[:, 1].max()
    assert np.allclose(lm[[0, 19, 31], 0], -lm[[9, 28, 37], 0], atol=2e-3)  # subject's right first, mirrored
    assert lm[:5, 0].max() < 0 < lm[5:10, 0].min()


def test_deterministic_and_cached(m, tmp_path, monkeypatch):
    again = build_default_model()
    assert all(np.array_equal(m[k], again[k]) for k in m)
    monkeypatch.setattr(default_model, "build_default_model", lambda: again)  # built and checked: not again
    monkeypatch.setenv("JAXMOCAP_CACHE", str(tmp_path))
    path = default_model_path()
    assert path.name == "SMPLX_NEUTRAL.npz" and path.parent.name == "smplx" and tmp_path in path.parents
    assert default_model_path() == path
    with np.load(path) as data:
        assert np.array_equal(data["v_template"], m["v_template"])
    write_default_model(tmp_path / "x" / "m.npz")
    assert [p.name for p in (tmp_path / "x").iterdir()] == ["m.npz"]


def test_generator_id_covers_every_file(tmp_path, monkeypatch):
    """The cache key hashes every file of ``smplx_jax/_default`` (no hand list): editing, adding or renaming any
    file, data included, changes it; byte-code caches do not."""
    import shutil

    copy = tmp_path / "_default"
    shutil.copytree(default_model._GENERATOR_DIR, copy, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(default_model, "_GENERATOR_DIR", copy)
    base = default_model.generator_id()
    assert base.startswith(f"v{default_model.GENERATOR_VERSION}-")
    ids = {base}
    for name in sorted(p.name for p in copy.glob("*.py")):
        with open(copy / name, "a") as fh:
            fh.write("\n# edited\n")
        ids.add(default_model.generator_id())
    assert len(ids) == 1 + len(list(copy.glob("*.py")))
    (copy / "table.npy").write_bytes(b"\x00")
    ids.add(default_model.generator_id())
    (copy / "table.npy").rename(copy / "table2.npy")
    ids.add(default_model.generator_id())
    assert len(ids) == 3 + len(list(copy.glob("*.py")))
    before = default_model.generator_id()
    (copy / "__pycache__").mkdir()
    (copy / "__pycache__" / "body.cpython-311.pyc").write_bytes(b"x")
    assert default_model.generator_id() == before


def test_smplx_package_runs_on_it():
    torch = pytest.importorskip("torch")
    smplx = pytest.importorskip("smplx")
    folder = default_model_path().parent.parent
    model = smplx.create(str(folder), model_type="smplx", use_pca=False, flat_hand_mean=True)
    out = model()
    assert out.joints.shape == (1, 127, 3) and out.vertices.shape == (1, 10475, 3)
    gen = torch.Generator().manual_seed(0)
    posed = model(body_pose=0.3 * torch.randn(1, 63, generator=gen), betas=torch.randn(1, 10, generator=gen),
                  expression=torch.randn(1, 10, generator=gen), jaw_pose=torch.tensor([[0.3, 0.0, 0.0]]),
                  left_hand_pose=0.3 * torch.randn(1, 45, generator=gen),
                  right_hand_pose=0.3 * torch.randn(1, 45, generator=gen))
    for t in (out.vertices, out.joints, posed.vertices, posed.joints):
        assert torch.isfinite(t).all()
    pca = smplx.create(str(folder), model_type="smplx", use_pca=True, num_pca_comps=12, flat_hand_mean=False)
    assert torch.isfinite(pca(left_hand_pose=torch.ones(1, 12)).joints).all()
    contour = smplx.create(str(folder), model_type="smplx", use_face_contour=True)
    turned = torch.zeros(1, 63)
    turned[0, 3 * 14 + 1] = 0.5  # head yaw
    for pose in (torch.zeros(1, 63), turned, -turned):
        joints = contour(body_pose=pose).joints[0]
        assert joints.shape == (144, 3) and torch.isfinite(joints).all()
        jaw_line = joints[127:]
        assert (jaw_line[:, 1] < joints[58:60, 1].min()).all()  # below the eyes
        assert (jaw_line[:8, 0] < jaw_line[9:, 0].min()).all()  # subject's right side first
