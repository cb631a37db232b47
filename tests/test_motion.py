"""motion.npz: round trip, dtypes and errors naming the key."""

import numpy as np
import pytest

from jaxmocap.errors import InputError
from jaxmocap.motion import MOTION_SHAPES, lens, read_motion, write_motion

T = 4


def _motion():
    shapes = {k: (T,) + tuple(10 if s == "B" else s for s in v) for k, v in MOTION_SHAPES.items() if v is not None}
    motion = {k: np.random.default_rng(0).normal(size=s) for k, s in shapes.items()}
    return motion | {"valid": np.array([1, 0, 1, 1], bool), "fps": np.array(30.0),
                     "image_size": np.array([640, 480]), "model_sha256": np.array("ab" * 32)}


def test_round_trip(tmp_path):
    motion = _motion()
    back = read_motion(write_motion(tmp_path / "m.npz", motion))
    assert back["body_pose"].dtype == np.float32 and back["valid"].dtype == bool
    np.testing.assert_allclose(back["body_pose"], motion["body_pose"], rtol=1e-6)
    assert str(back["model_sha256"]) == "ab" * 32 and list(tmp_path.iterdir()) == [tmp_path / "m.npz"]


def test_errors_name_the_key(tmp_path):
    bad = _motion() | {"body_pose": np.zeros((T, 22, 3))}
    with pytest.raises(InputError, match=r"key 'body_pose' has shape \(4, 22, 3\), expected \(4, 21, 3\)"):
        write_motion(tmp_path / "m.npz", bad)
    assert not (tmp_path / "m.npz").exists()
    np.savez(tmp_path / "partial.npz", **{k: v for k, v in _motion().items() if k != "fps"})
    with pytest.raises(InputError, match=r"lacks the motion key\(s\) fps"):
        read_motion(tmp_path / "partial.npz")
    (tmp_path / "junk.npz").write_bytes(b"junk")
    with pytest.raises(InputError, match="not a readable motion"):
        read_motion(tmp_path / "junk.npz")


def test_the_pinhole_camera_keys_come_together(tmp_path):
    pinhole = {"focal_length": np.array(1440.0), "principal_point": np.array([540.0, 960.0])}
    back = read_motion(write_motion(tmp_path / "m.npz", _motion() | pinhole))
    assert lens(back) == (1440.0, pytest.approx([540.0, 960.0])) and lens(_motion()) == (None, None)
    for bad, message in (({"focal_length": np.array(1440.0)}, "'focal_length' without 'principal_point'"),
                         (pinhole | {"principal_point": np.zeros(3)}, r"'principal_point' has shape \(3,\)"),
                         (pinhole | {"focal_length": np.array(-1.0)}, "focal_length must be positive")):
        with pytest.raises(InputError, match=message):
            write_motion(tmp_path / "bad.npz", _motion() | bad)
