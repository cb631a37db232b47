"""Loading model files: .npz and .pkl (numpy, chumpy leaves, scipy sparse), and clear errors."""

import pickle
import pickletools
import struct
import sys
import types

import numpy as np
import pytest

import smplx_jax
from conftest import load
from jaxmocap.export.frankmocap import _Numpy1Pickler
from random_model import random_model_arrays
from smplx_jax import ModelFileError, ModelNotFoundError


@pytest.fixture(scope="module")
def arrays():
    return random_model_arrays(seed=2)


def _save(tmp_path, arrays, name="SMPLX_NEUTRAL.npz"):
    path = tmp_path / name
    np.savez(path, **arrays)
    return path


def test_missing_file_says_where_to_get_a_model(tmp_path):
    with pytest.raises(ModelNotFoundError, match=r"not found.*smpl-x.*jaxmocap model"):
        smplx_jax.load_model(tmp_path / "nope" / "SMPLX_NEUTRAL.npz")


def test_missing_key_is_named(tmp_path, arrays):
    path = _save(tmp_path, {k: v for k, v in arrays.items() if k != "posedirs"})
    with pytest.raises(ModelFileError, match=r"SMPLX_NEUTRAL.npz lacks the SMPL-X key\(s\) posedirs"):
        smplx_jax.load_model(path)


@pytest.mark.parametrize("key, bad", [
    ("posedirs", lambda a: a[:, :, :100]),
    ("weights", lambda a: a[:, :24]),
    ("J_regressor", lambda a: a[:24]),
    ("v_template", lambda a: a[:, :2]),
    ("lmk_bary_coords", lambda a: a[:10]),
    ("hands_meanl", lambda a: a[:30]),
])
def test_wrong_shape_is_named(tmp_path, arrays, key, bad):
    path = _save(tmp_path, arrays | {key: bad(arrays[key])})
    with pytest.raises(ModelFileError, match=rf"key '{key}' has shape"):
        smplx_jax.load_model(path)


def test_bad_values(tmp_path, arrays):
    with pytest.raises(ModelFileError, match="'f' indexes vertices outside"):
        smplx_jax.load_model(_save(tmp_path, arrays | {"f": arrays["f"] + 20000}))
    bad = arrays["shapedirs"].copy()
    bad[5, 1, 3] = np.nan
    with pytest.raises(ModelFileError, match="'shapedirs' holds NaN"):
        smplx_jax.load_model(_save(tmp_path, arrays | {"shapedirs": bad}))


def test_corrupt_and_unknown_files(tmp_path):
    (tmp_path / "bad.npz").write_bytes(b"PK\x03\x04 not a zip at all")
    with pytest.raises(ModelFileError, match="not a readable .npz"):
        smplx_jax.load_model(tmp_path / "bad.npz")
    (tmp_path / "bad.pkl").write_bytes(b"\x80\x04garbage")
    with pytest.raises(ModelFileError, match="not a readable .pkl"):
        smplx_jax.load_model(tmp_path / "bad.pkl")
    (tmp_path / "model.obj").write_text("v 0 0 0")
    with pytest.raises(ModelFileError, match="unknown model file type"):
        smplx_jax.load_model(tmp_path / "model.obj")


def test_too_many_betas_requested(tmp_path, arrays):
    with pytest.raises(ValueError, match="num_betas=301"):
        smplx_jax.load_model(_save(tmp_path, arrays), num_betas=301)


def _fake_modules(monkeypatch):
    """Stand-ins for chumpy's Ch and scipy's csc_matrix so that pickles refer to them by name, as the
    official .pkl files do; the loader must not import either."""
    ch = types.ModuleType("chumpy.ch")
    sparse = types.ModuleType("scipy.sparse._csc")

    class Ch:
        def __init__(self, x):
            self.x = x

    class csc_matrix:  # noqa: N801
        def __init__(self, dense):
            nz = dense.T.nonzero()
            self.data, self.indices = dense.T[nz], nz[1].astype(np.int32)
            self.indptr = np.concatenate([[0], np.cumsum(np.bincount(nz[0], minlength=dense.shape[1]))])
            self._shape = dense.shape

    Ch.__module__, Ch.__qualname__ = "chumpy.ch", "Ch"
    csc_matrix.__module__, csc_matrix.__qualname__ = "scipy.sparse._csc", "csc_matrix"
    ch.Ch, sparse.csc_matrix = Ch, csc_matrix
    for name, module in (("chumpy", types.ModuleType("chumpy")), ("chumpy.ch", ch),
                         ("scipy", types.ModuleType("scipy")), ("scipy.sparse", types.ModuleType("scipy.sparse")),
                         ("scipy.sparse._csc", sparse)):
        monkeypatch.setitem(sys.modules, name, module)
    return Ch, csc_matrix


class _Python2Pickler(_Numpy1Pickler):
    """Pickles as Python 2 and NumPy 1.x did the official files: bytes as Python 2's ``str`` (BINSTRING), numpy's
    functions from ``numpy.core``, ``copy_reg`` and ``__builtin__`` for objects."""

    def save_bytes(self, obj):
        self.write(pickle.BINSTRING + struct.pack("<I", len(obj)) + obj)
        self.memoize(obj)

    dispatch = _Numpy1Pickler.dispatch | {bytes: save_bytes}


@pytest.mark.parametrize("writer, protocol", [("python2", 2), ("python2", 1), ("python3", 5)])
def test_pkl_with_chumpy_and_sparse_arrays_loads_like_npz(tmp_path, arrays, monkeypatch, writer, protocol):
    Ch, csc_matrix = _fake_modules(monkeypatch)
    data = dict(arrays, v_template=Ch(arrays["v_template"]), shapedirs=Ch(arrays["shapedirs"]),
                J_regressor=csc_matrix(arrays["J_regressor"]))
    with open(tmp_path / "SMPLX_NEUTRAL.pkl", "wb") as fh:
        (_Python2Pickler(fh, protocol=protocol) if writer == "python2" else pickle.Pickler(fh, protocol)).dump(data)
    names = {arg for op, arg, _ in pickletools.genops((tmp_path / "SMPLX_NEUTRAL.pkl").read_bytes())
             if op.name == "GLOBAL"}
    if writer == "python2":
        assert "numpy.core.multiarray _reconstruct" in names
        assert ("copy_reg _reconstructor" in names) == (protocol == 1)
    monkeypatch.undo()  # chumpy and scipy are gone again while loading
    from_pkl = smplx_jax.load_model(tmp_path / "SMPLX_NEUTRAL.pkl")
    from_npz = smplx_jax.load_model(_save(tmp_path, arrays))
    for name in ("template_cm", "shapedirs_cm", "joint_template", "joint_shapedirs", "posedirs_cm"):
        np.testing.assert_array_equal(np.asarray(getattr(from_pkl, name)), np.asarray(getattr(from_npz, name)))


def test_pkl_with_chumpy_expression_is_refused(tmp_path, arrays, monkeypatch):
    Ch, _ = _fake_modules(monkeypatch)
    derived = Ch(None)
    del derived.x  # a chumpy expression has no stored value
    derived.a = 1
    with open(tmp_path / "m.pkl", "wb") as fh:
        pickle.dump(dict(arrays, shapedirs=derived), fh, protocol=2)
    monkeypatch.undo()
    with pytest.raises(ModelFileError, match="'shapedirs' is a pickled chumpy expression"):
        smplx_jax.load_model(tmp_path / "m.pkl")


def test_default_model_loads(default_model_dir):
    model = load(default_model_dir)
    assert model.num_vertices == 10475 and model.num_betas == 10 and model.num_expression == 10


def test_an_unchanged_file_is_loaded_once_and_a_rewritten_one_again(tmp_path, arrays):
    path = _save(tmp_path, arrays)
    first = smplx_jax.load_model(path)
    assert smplx_jax.load_model(str(path)) is first  # the same file, given as a string
    assert smplx_jax.load_model(path, num_expression=4) is not first
    assert smplx_jax.load_model(path, num_betas=8).num_betas == 8
    path.unlink()
    with pytest.raises(ModelNotFoundError):  # a file no longer there is not served from memory
        smplx_jax.load_model(path)
    moved = dict(arrays, v_template=arrays["v_template"] + 1.0)  # the same size, other values
    _save(tmp_path, moved)
    np.testing.assert_allclose(np.asarray(smplx_jax.load_model(path).v_template), moved["v_template"], rtol=1e-6)
