"""Reading and checking SMPL-X model files (``.npz`` and ``.pkl``) into plain float64 numpy arrays."""

import zipfile
from pathlib import Path

import numpy as np

from smplx_jax import constants, safe_pickle

REQUIRED_KEYS = (
    "v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "f",
    "hands_componentsl", "hands_componentsr", "hands_meanl", "hands_meanr", "lmk_faces_idx", "lmk_bary_coords",
)
_GET_SMPLX = (
    "Download SMPL-X (registration required) from https://smpl-x.is.tue.mpg.de, or use the built-in "
    "license-free model: smplx_jax.default_model_path() in Python, `jaxmocap model --out PATH` on the command line."
)


class ModelFileError(ValueError):
    """A model file (the body model, or one of jaxmocap's detector models) is missing, unreadable, corrupt or not
    what it should be; the message says which and what to do."""


class ModelNotFoundError(ModelFileError, FileNotFoundError):
    """The body model file does not exist."""


def read_model_file(path: Path) -> dict[str, np.ndarray]:
    """The checked arrays of an SMPL-X file; ``parents`` replaces ``kintree_table``."""
    if not path.is_file():
        raise ModelNotFoundError(f"SMPL-X model file not found: {path}. {_GET_SMPLX}")
    if path.suffix == ".npz":
        raw = _read_npz(path)
    elif path.suffix == ".pkl":
        raw = _read_pkl(path)
    else:
        raise ModelFileError(f"{path}: unknown model file type {path.suffix!r} (expected .npz or .pkl)")
    missing = [k for k in REQUIRED_KEYS if k not in raw]
    if missing:
        raise ModelFileError(f"{path} lacks the SMPL-X key(s) {', '.join(missing)}; is it an SMPL-X model file?")
    return _check(path, {k: _dense(raw[k]) for k in REQUIRED_KEYS})


def _read_npz(path):
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in REQUIRED_KEYS if k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
        raise ModelFileError(f"{path} is not a readable .npz model file ({err})") from None


def _read_pkl(path):
    try:
        with open(path, "rb") as fh:
            data = safe_pickle.load(fh, _stand_in)
    except safe_pickle.RefusedPickle as err:
        raise ModelFileError(
            f"{path} refers to {err.reference}, which an SMPL-X, SMPL-H or MANO model file does not hold: "
            "refused before anything in it was run") from None
    except Exception as err:  # a corrupt pickle can raise almost anything
        raise ModelFileError(f"{path} is not a readable .pkl model file ({type(err).__name__}: {err})") from None
    if not isinstance(data, dict):
        raise ModelFileError(f"{path} holds a {type(data).__name__}, not the dict of an SMPL-X .pkl file")
    for key, value in data.items():
        if isinstance(value, _Chumpy):
            data[key] = value.array(path, key)
    return data


class _Chumpy:
    """Stands in for a pickled chumpy ``Ch`` (chumpy need not be installed); only its value is kept."""

    def __setstate__(self, state):
        self.state = state

    def array(self, path, key):
        if not isinstance(getattr(self, "state", None), dict) or "x" not in self.state:
            raise ModelFileError(
                f"{path}: key {key!r} is a pickled chumpy expression, not an array; convert the file with "
                "smplx's tools/clean_ch.py (in an environment with chumpy) or use the .npz release")
        return np.asarray(self.state["x"])


class _Sparse:
    """Stands in for a pickled scipy.sparse CSR/CSC matrix (scipy need not be installed)."""

    by_columns = False

    def __setstate__(self, state):
        self.state = state

    def toarray(self):
        s = self.state
        out = np.zeros(s.get("_shape", s.get("shape")))
        major = np.repeat(np.arange(len(s["indptr"]) - 1), np.diff(s["indptr"]))
        rows, cols = (s["indices"], major) if self.by_columns else (major, s["indices"])
        out[rows, cols] = s["data"]
        return out


class _Csc(_Sparse):
    by_columns = True


_SPARSE = {"csr_matrix": _Sparse, "csr_array": _Sparse, "csc_matrix": _Csc, "csc_array": _Csc}


def _stand_in(module: str, name: str) -> type | None:
    """The inert class read in place of a chumpy ``Ch`` (any chumpy class: only a stored value is kept) or a scipy
    CSR/CSC matrix, as the official ``.pkl`` files hold them; None for anything else."""
    if module.split(".")[0] == "chumpy":
        return _Chumpy
    if module in ("scipy.sparse.csr", "scipy.sparse._csr", "scipy.sparse.csc", "scipy.sparse._csc"):
        return _SPARSE.get(name)
    return None


def _dense(value):
    if isinstance(value, _Sparse):
        return value.toarray()
    return np.asarray(value)


def _check(path, raw):
    """Shapes, index ranges and finiteness; returns float64 arrays and ``parents``."""

    def fail(key, expected, actual):
        raise ModelFileError(f"{path}: key {key!r} has shape {actual}, expected {expected}")

    def numeric(key, kind=np.number):
        if not np.issubdtype(raw[key].dtype, kind):
            raise ModelFileError(f"{path}: key {key!r} has dtype {raw[key].dtype}, expected numbers")
        return raw[key]

    v_template = numeric("v_template")
    if v_template.ndim != 2 or v_template.shape[1] != 3:
        fail("v_template", "(V, 3)", v_template.shape)
    num_vertices = v_template.shape[0]
    if num_vertices <= max(constants.VERTEX_JOINT_IDS):
        fail("v_template", f"(V, 3), V > {max(constants.VERTEX_JOINT_IDS)} (SMPL-X vertex joints)", v_template.shape)
    j, p = constants.NUM_JOINTS, 9 * (constants.NUM_JOINTS - 1)
    shapedirs = numeric("shapedirs")
    if shapedirs.ndim != 3 or shapedirs.shape[:2] != (num_vertices, 3) or shapedirs.shape[2] < 20:
        fail("shapedirs", f"({num_vertices}, 3, S) with S >= 20", shapedirs.shape)
    expected = {
        "posedirs": (num_vertices, 3, p), "J_regressor": (j, num_vertices), "weights": (num_vertices, j),
        "kintree_table": (2, j), "hands_meanl": (45,), "hands_meanr": (45,),
    }
    for key, shape in expected.items():
        if numeric(key).shape != shape:
            fail(key, shape, raw[key].shape)
    for key in ("hands_componentsl", "hands_componentsr"):
        if numeric(key).ndim != 2 or raw[key].shape[1] != 45:
            fail(key, "(C, 45)", raw[key].shape)
    faces = numeric("f", np.integer)
    if faces.ndim != 2 or faces.shape[1] != 3:
        fail("f", "(F, 3)", faces.shape)
    if faces.min() < 0 or faces.max() >= num_vertices:
        raise ModelFileError(f"{path}: key 'f' indexes vertices outside 0..{num_vertices - 1}")
    lmk_faces = numeric("lmk_faces_idx", np.integer).ravel()
    if lmk_faces.shape != (constants.NUM_LANDMARKS,):
        fail("lmk_faces_idx", (constants.NUM_LANDMARKS,), raw["lmk_faces_idx"].shape)
    if lmk_faces.min() < 0 or lmk_faces.max() >= len(faces):
        raise ModelFileError(f"{path}: key 'lmk_faces_idx' indexes faces outside 0..{len(faces) - 1}")
    if numeric("lmk_bary_coords").shape != (constants.NUM_LANDMARKS, 3):
        fail("lmk_bary_coords", (constants.NUM_LANDMARKS, 3), raw["lmk_bary_coords"].shape)

    parents = raw["kintree_table"][0].astype(np.int64)
    parents[0] = -1
    if np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, j)):
        raise ModelFileError(f"{path}: key 'kintree_table' does not list each joint's parent before the joint")
    integer_keys = ("f", "lmk_faces_idx", "kintree_table")
    out = {k: np.asarray(v, dtype=np.float64) for k, v in raw.items() if k not in integer_keys}
    for key, value in out.items():
        if not np.all(np.isfinite(value)):
            raise ModelFileError(f"{path}: key {key!r} holds NaN or infinite values")
    return out | {"f": faces.astype(np.int64), "lmk_faces_idx": lmk_faces.astype(np.int64), "parents": parents}
