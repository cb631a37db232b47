"""No crafted pickle runs code through a loader of the project: model files (`load_model`, `jaxmocap run --model`),
the FrankMocap converter (`--hand-mean`, and `--hand` through torch's loader) and the dataset readers.

Each payload is live: a plain ``pickle.load`` of it creates its marker file (checked here, so that a payload which
stopped working cannot make these tests pass). Each loader must refuse it by name, in one line, and leave no marker.
"""

import os
import pickle
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from numpy.testing._private.utils import runstring

import smplx_jax
from jaxmocap.cli import main
from random_model import random_model_arrays
from train.datasets import rhd
from train.datasets.hand_joints import load_pickled_dict

CLIP = Path(__file__).parents[1] / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"
PAYLOADS = ("runstring", "ctypeslib", "numpy.load", "exec", "os.system")
REFERENCE = {"runstring": r"numpy\.testing\._private\.utils\.runstring", "ctypeslib": r"numpy\.ctypeslib\.load_library",
             "numpy.load": r"numpy\.load", "exec": r"(builtins|__builtin__)\.exec", "os.system": r"posix\.system"}
"""What each payload refers to, as a pattern (protocol 2 names builtins as Python 2 did)."""


class Call:
    """Pickles as the call ``function(*args)``, which is what a crafted file makes ``pickle.load`` do."""

    def __init__(self, function, *args):
        self.function, self.args = function, args

    def __reduce__(self):
        return self.function, self.args


def payload(kind: str, folder: Path) -> tuple[Call, Path]:
    """A call that creates ``folder/marker`` when unpickled, and that marker's path."""
    folder.mkdir(parents=True, exist_ok=True)
    marker = folder / "marker"
    touch = f"open({str(marker)!r}, 'w').close()"
    if kind == "runstring":
        return Call(runstring, touch, {}), marker
    if kind == "ctypeslib":  # a shared library whose constructor creates the marker, loaded by numpy
        (folder / "touch.c").write_text('#include <stdio.h>\n__attribute__((constructor)) static void touch(void) '
                                        f'{{ FILE *f = fopen("{marker}", "w"); if (f) fclose(f); }}\n')
        subprocess.run(["cc", "-shared", "-fPIC", "-o", str(folder / "libtouch.so"), str(folder / "touch.c")],
                       check=True)
        return Call(np.ctypeslib.load_library, "libtouch", str(folder)), marker
    if kind == "numpy.load":  # numpy.load unpickles a second file, with plain pickle
        np.save(folder / "inner.npy", np.array([Call(exec, touch)], dtype=object), allow_pickle=True)
        return Call(np.load, str(folder / "inner.npy"), None, True), marker
    if kind == "exec":
        return Call(exec, touch), marker
    return Call(os.system, f"touch {marker}"), marker


@pytest.fixture(scope="module")
def arrays():
    """A model file's keys with small arrays: the loader refuses a payload by name before it reads any array, and
    pickling the official sizes with protocol 2 takes seconds a file."""
    return random_model_arrays(seed=2, num_vertices=300, num_faces=500)


@pytest.mark.parametrize("kind", PAYLOADS)
def test_each_payload_runs_under_a_plain_pickle_load(tmp_path, kind):
    call, marker = payload(kind, tmp_path)
    pickle.loads(pickle.dumps({"v_template": call}, protocol=2))
    assert marker.exists()


@pytest.mark.parametrize("protocol", [2, 5])
@pytest.mark.parametrize("kind", PAYLOADS)
def test_load_model_refuses_code_by_name(tmp_path, arrays, kind, protocol):
    call, marker = payload(kind, tmp_path / "payload")
    path = tmp_path / "SMPLX_NEUTRAL.pkl"
    path.write_bytes(pickle.dumps(dict(arrays, v_template=call), protocol=protocol))
    with pytest.raises(smplx_jax.ModelFileError) as error:
        smplx_jax.load_model(path)
    assert re.fullmatch(f"{re.escape(str(path))} refers to {REFERENCE[kind]}, which an SMPL-X, SMPL-H or MANO "
                        "model file does not hold: refused before anything in it was run", str(error.value))
    assert not marker.exists()


def test_run_with_a_crafted_model_fails_in_one_line_and_runs_nothing(tmp_path, arrays, capsys):
    call, marker = payload("runstring", tmp_path / "payload")
    (tmp_path / "evil.pkl").write_bytes(pickle.dumps(dict(arrays, shapedirs=call), protocol=2))
    code = main(["run", str(CLIP), "--model", str(tmp_path / "evil.pkl"), "--out", str(tmp_path / "out"), "--quiet",
                 "--end", "2"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "refers to numpy.testing._private.utils.runstring" in err
    assert not marker.exists()


@pytest.mark.parametrize("kind", PAYLOADS)
def test_converter_refuses_a_crafted_hand_mean(tmp_path, kind, capsys):
    import torch

    call, marker = payload(kind, tmp_path / "payload")
    torch.save({"main_encoder.fc1.bias": torch.zeros(1)}, tmp_path / "hand.pth")
    (tmp_path / "mean_mano_params.pkl").write_bytes(pickle.dumps({"mean_pose": call}, protocol=2))
    code = main(["convert-frankmocap", "--hand", str(tmp_path / "hand.pth"), "--hand-mean",
                 str(tmp_path / "mean_mano_params.pkl"), "--body", str(tmp_path / "none.pt"), "--out",
                 str(tmp_path / "weights")])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and re.search(f"refers to {REFERENCE[kind]}, which", err), err
    assert not marker.exists()


def test_converter_refuses_a_crafted_checkpoint(tmp_path, capsys):
    """``--hand`` and ``--body`` go through torch's own restricted loader (``weights_only=True``)."""
    import torch

    call, marker = payload("exec", tmp_path / "payload")
    torch.save({"conv1.weight": call}, tmp_path / "pose_shape_best.pth")
    code = main(["convert-frankmocap", "--hand", str(tmp_path / "pose_shape_best.pth"), "--hand-mean",
                 str(tmp_path / "mean.pkl"), "--body", str(tmp_path / "none.pt"), "--out", str(tmp_path / "w")])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and "cannot read as a PyTorch checkpoint" in err, err
    assert not marker.exists()
    torch.load(tmp_path / "pose_shape_best.pth", weights_only=False)  # the payload is live
    assert marker.exists()


@pytest.mark.parametrize("kind", PAYLOADS)
def test_dataset_annotations_refuse_code(tmp_path, kind):
    call, marker = payload(kind, tmp_path / "payload")
    (tmp_path / "training").mkdir()
    path = tmp_path / "training" / "anno_training.pickle"
    path.write_bytes(pickle.dumps({0: {"uv_vis": call}}, protocol=2))
    with pytest.raises(ValueError, match=rf"anno_training.pickle refers to {REFERENCE[kind]}, which .* does not"):
        rhd.read(tmp_path, "train")
    with pytest.raises(ValueError, match=f"refers to {REFERENCE[kind]}"):
        load_pickled_dict(path, "a pickled dict of HO-3D labels")
    assert not marker.exists()


def test_annotations_of_arrays_still_load(tmp_path):
    values = {7: {"xyz": np.arange(6.0).reshape(2, 3), "K": np.eye(3, dtype=np.float32), "name": "a", "n": None}}
    for protocol in (0, 2, 5):
        path = tmp_path / f"anno_{protocol}.pickle"
        path.write_bytes(pickle.dumps(values, protocol=protocol))
        loaded = load_pickled_dict(path, "a dict")
        np.testing.assert_array_equal(loaded[7]["xyz"], values[7]["xyz"])
        assert loaded[7]["K"].dtype == np.float32 and loaded[7]["name"] == "a" and loaded[7]["n"] is None

