"""FrankMocap's regressors: our flax networks against the PyTorch reference through the importer, the crops
against FrankMocap's (transcribed) preprocessing, batching, and the importer's errors."""

import json

import jax
import numpy as np
import pytest
import torch
from flax import nnx

import frankmocap_reference as ref
import jaxmocap.regressors as R
import smplx_jax
from conftest import load, programs_lowered
from jaxmocap.cli import main
from jaxmocap.regressors import crops

TOL = 1e-4


@pytest.fixture(scope="module")
def checkpoints(frankmocap):
    """FrankMocap-format files of random reference networks (hand .pth state_dict, {'model': ...} body .pt)."""
    return frankmocap


def _convert(root, out, hand="pose_shape_best.pth", body="body.pt", mean="mean_mano_params.pkl"):
    return main(["convert-frankmocap", "--hand", str(root / hand), "--hand-mean", str(root / mean),
                 "--body", str(root / body), "--out", str(out)])


@pytest.fixture(scope="module")
def converted(checkpoints):
    return checkpoints[0] / "weights"  # converted by conftest's `frankmocap`


@pytest.fixture(scope="module")
def predictor(converted):
    return R.Predictor(R.load(converted), buckets=(1, 8))


@pytest.mark.parametrize("batch", [1, 7])
def test_networks_match_pytorch(checkpoints, predictor, batch):
    _, hand, body = checkpoints
    x = np.random.default_rng(batch).normal(0, 1, (batch, 224, 224, 3)).astype(np.float32)
    with torch.no_grad():
        nchw = torch.from_numpy(x).permute(0, 3, 1, 2)
        hand_ref, body_ref = hand(nchw).numpy(), [t.numpy() for t in body(nchw)]
    hand_out, body_out = np.asarray(predictor.hand(x)), predictor.body(x)
    assert hand_out.shape == (batch, 61) and np.abs(hand_out - hand_ref).max() <= TOL
    assert body_out.rotmats.shape == (batch, 24, 3, 3) and body_out.betas.shape == (batch, 10)
    for ours, theirs in zip(body_out, body_ref):
        assert np.abs(np.asarray(ours) - theirs).max() <= TOL
    assert np.abs(hand_ref).max() > 1 and np.abs(body_ref[1]).max() > 1  # outputs are not trivially small


def test_microbatches_match_whole_batches(converted, predictor):
    x = np.random.default_rng(9).normal(0, 1, (6, 224, 224, 3)).astype(np.float32)
    chunked = R.Predictor(R.load(converted), buckets=(8,), microbatch=4)  # one bucket, two chunks of 4
    assert np.abs(np.asarray(chunked.hand(x)) - np.asarray(predictor.hand(x))).max() <= 1e-5


def test_initialised_is_the_network_built_eagerly():
    """`initialised` (the initialisers compiled as one program at -O0) gives the network built eagerly: the same
    graph and, rounding aside, the same weights."""
    def new():
        rngs = nnx.Rngs(3)
        return nnx.Sequential(nnx.Conv(3, 8, (3, 3), rngs=rngs), nnx.BatchNorm(8, rngs=rngs),
                              nnx.Linear(8, 5, rngs=rngs))

    (eager_graph, eager), (graph, state) = nnx.split(new()), nnx.split(R.initialised(new))
    assert graph == eager_graph
    leaves, eager_leaves = jax.tree.leaves(state), jax.tree.leaves(eager)
    assert len(leaves) == len(eager_leaves) == 8 and any(np.ptp(np.asarray(a)) > 0.1 for a in leaves)
    for a, b in zip(leaves, eager_leaves):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-6, atol=1e-7)


def test_weights_are_pickle_free(converted):
    index = json.loads((converted / "regressors.json").read_text())
    assert index["hand"]["config"] == {"depth": 50, "hidden": 1024}
    for kind in ("hand", "body"):
        with np.load(converted / index[kind]["file"], allow_pickle=False) as npz:
            assert all(npz[name].dtype == np.float32 for name in npz.files)
    with np.load(converted / "hand.npz") as npz:
        assert npz["mean_params"][:3].tolist() == [5, 0, 0]


def test_ragged_batches_do_not_recompile(predictor):
    x = np.zeros((11, 224, 224, 3), np.float32)
    for n in (1, 3):  # one size of each bucket the sizes below fall in (the fixture's: 1, 8)
        predictor.hand(x[:n])
    with programs_lowered() as lowered:
        for n in (0, 1, 2, 5, 8, 11):
            assert predictor.hand(x[:n]).shape == (n, 61)
    assert "jit(_apply)" not in lowered


def _image(height, width, seed=0):
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)


BOXES = [(50.3, 60.7, 80, 120), (-10, -5, 60, 40), (330, 250, 100, 90), (0, 0, 400, 300), (10.9, 10.2, 8, 30),
         (200, 20, 3, 2)]


@pytest.mark.parametrize("kind", ["body", "hand"])
@pytest.mark.parametrize("size", [(300, 400), (400, 250)])
def test_crops_match_frankmocap(kind, size):
    img = _image(*size)
    windows = (crops.body_windows if kind == "body" else crops.hand_windows)(np.array(BOXES), size[::-1])
    out = np.asarray(crops.crop(img[None], 0, windows))
    for i, box in enumerate(BOXES):
        expected = (ref.body_crop if kind == "body" else ref.hand_crop)(img, box)
        assert windows.ok[i] == (expected is not None)
        if expected is None:
            continue
        crop, ratio, top_left = expected
        assert np.array_equal(windows.origin[i], top_left) and np.isclose(windows.ratio[i], ratio)
        diff = np.abs(out[i] - crop)  # OpenCV's fixed-point rounding differs by at most one level
        assert diff.max() <= 1 and diff.mean() < 0.2


def test_crop_lands_where_expected():
    img = np.zeros((480, 640, 3), np.uint8)
    img[98:102, 198:202] = (0, 0, 255)  # a red marker (BGR) at the box centre
    img[50:60, 100:110] = (255, 0, 0)  # a blue one at the box's top-left
    window = crops.body_windows(np.array([[100.0, 50, 200, 100]]), (640, 480))  # side 240, origin (80, -20)
    out = np.asarray(crops.crop(img[None], 0, window))[0]
    scale = 224 / 240
    red = np.argwhere(out[..., 2] > 128).mean(axis=0)
    blue = np.argwhere(out[..., 0] > 128).mean(axis=0)
    assert np.allclose(red, [112 - 0.5, 112 - 0.5], atol=0.6)
    assert np.allclose(blue, [(55 + 20) * scale - 0.5, (105 - 80) * scale - 0.5], atol=0.6)
    assert out[:10].max() == 0  # above the image: zero padding
    rgb = np.asarray(crops.normalize_body(out[None]))[0, 112, 112]
    assert rgb[0] == pytest.approx((1 - 0.485) / 0.229, abs=1e-5)  # red is channel 0 after BGR -> RGB


def test_left_hand_flip_round_trip():
    img = _image(200, 300)
    window = crops.hand_windows(np.array([[40.0, 30, 50, 70], [200, 120, 90, 60]]), (300, 200))
    plain = np.asarray(crops.crop(img[None], 0, window))
    flipped = np.asarray(crops.crop(img[None], 0, window, flip=np.array([True, False])))
    assert np.array_equal(flipped[0], plain[0, :, ::-1]) and np.array_equal(flipped[1], plain[1])
    raw = np.random.default_rng(0).normal(size=(5, 61)).astype(np.float32)
    mirrored = np.asarray(R.mirror_hand_params(raw))
    assert np.array_equal(np.asarray(R.mirror_hand_params(mirrored)), raw)
    assert np.array_equal(mirrored[:, [0, 2]], raw[:, [0, 2]]) and np.array_equal(mirrored[:, 1], -raw[:, 1])
    aa_raw, aa_mir = raw[:, 3:51].reshape(5, 16, 3), mirrored[:, 3:51].reshape(5, 16, 3)
    assert np.array_equal(aa_mir[..., 0], aa_raw[..., 0]) and np.array_equal(aa_mir[..., 1:], -aa_raw[..., 1:])
    assert np.array_equal(mirrored[:, 51:], raw[:, 51:])


def test_camera_maps_to_image():
    window = crops.body_windows(np.array([[100.0, 50, 200, 100]]), (640, 480))  # side 240, origin (80, -20)
    points = np.array([[[0.0, 0, 0], [0.5, -0.25, 3]]], np.float32)
    assert np.abs(window.origin[0] - [80, -20]).max() <= 1 and abs(window.ratio[0] - 224 / 240) < 0.01
    (x0, y0), half = window.origin[0], 112 / window.ratio[0]  # half the crop, in image pixels
    body = np.asarray(crops.body_to_image(points, np.array([[2.0, 0.1, -0.2]], np.float32), window))[0]
    assert np.allclose(body[0], [x0 + (0.1 + 1) * half, y0 + (-0.2 + 1) * half], atol=1e-3)
    assert np.allclose(body[1], [x0 + (1.0 + 0.1 + 1) * half, y0 + (-0.5 - 0.2 + 1) * half], atol=1e-3)
    hand = np.asarray(crops.hand_to_image(points, np.array([[2.0, 0.1, -0.2]], np.float32), window))[0]
    assert np.allclose(hand[1], [x0 + ((0.5 + 0.1) * 2 + 1) * half, y0 + ((-0.25 - 0.2) * 2 + 1) * half], atol=1e-3)


def test_missing_hand_skips_its_crop(predictor):
    images = np.stack([_image(200, 300, seed) for seed in (1, 2)])
    boxes = np.array([[40.0, 30, 50, 70], [np.nan] * 4, [150, 100, 60, 60]])
    raw, window, valid = R.predict_hands(predictor, images, [0, 1, 1], boxes, [False, False, True])
    assert valid.tolist() == [True, False, True] and np.all(np.isnan(np.asarray(raw[1])))
    sub = crops.Window(*(np.asarray(a)[[0, 2]] for a in window))
    expected = predictor.hand(crops.normalize_hand(crops.crop(images, np.array([0, 1]), sub,
                                                              flip=np.array([False, True]))))
    assert np.abs(np.asarray(raw)[[0, 2]] - np.asarray(expected)).max() <= 1e-5
    with programs_lowered() as lowered:
        for present in ([True, True, False], [True, True, True], [False, False, False]):  # all in bucket 8
            ragged = np.where(np.array(present)[:, None], boxes[[0, 0, 2]], np.nan)
            raw, _, valid = R.predict_hands(predictor, images, [0, 1, 1], ragged, False)
            assert valid.tolist() == present and raw.shape == (3, 61)
    assert not {"jit(_sample)", "jit(_apply)"} & set(lowered), lowered  # no recompiles


@pytest.fixture(scope="module")
def body_model(default_model_dir):
    return load(default_model_dir)


def test_left_hand_decodes_to_the_mirror_image(body_model):
    model = body_model
    raw = np.random.default_rng(3).normal(0, 0.2, (1, 61)).astype(np.float32)
    raw[:, 0] = 6.0
    window = crops.hand_windows(np.array([[100.0, 100, 60, 60]] * 2), (640, 480))
    out = R.decode_hands(model, smplx_jax.hand_model(model, "right"), np.repeat(raw, 2, 0), np.array([False, True]),
                         window)
    centre = window.origin[0, 0] + 112 / window.ratio[0]
    joints = np.asarray(out.joints_2d)
    assert np.allclose(joints[1, :, 0], 2 * centre - joints[0, :, 0], atol=1e-3)
    assert np.allclose(joints[1, :, 1], joints[0, :, 1], atol=1e-3)
    assert np.allclose(out.hand_pose[0], raw[0, 6:51].reshape(15, 3) + model.hand_mean[1].reshape(15, 3), atol=1e-6)
    assert np.allclose(out.camera[1], raw[0, :3] * [1, -1, 1])


def test_body_decodes_to_smplx(predictor, body_model):
    x = np.random.default_rng(5).normal(0, 1, (3, 224, 224, 3)).astype(np.float32)
    out = predictor.body(x)
    window = crops.body_windows(np.array([[100.0, 50, 200, 300]] * 3), (640, 480))
    decoded = R.decode_bodies(body_model, out, window)
    params = decoded.params
    assert params.body_pose.shape == (3, 21, 3) and params.betas.shape == (3, 10)
    rotvecs = np.concatenate([params.global_orient[:, None], params.body_pose], axis=1)
    rotmats = np.asarray(smplx_jax.rotations.rotvec_to_rotmat(rotvecs))
    assert np.abs(rotmats - np.asarray(out.rotmats)[:, :22]).max() < 1e-5
    assert np.allclose(params.right_hand_pose, np.broadcast_to(body_model.hand_mean[1].reshape(15, 3), (3, 15, 3)))
    joints = jax.jit(jax.vmap(smplx_jax.forward_joints, in_axes=(None, 0)))(body_model, params)
    expected = crops.body_to_image(joints, out.camera, window)
    assert decoded.joints_2d.shape == (3, 127, 2) and np.abs(decoded.joints_2d - expected).max() < 1e-3


def _expect_error(capsys, code, *needles):
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and all(n in err for n in needles), err


def test_body_given_as_hand_is_an_error(checkpoints, tmp_path, capsys):
    _expect_error(capsys, _convert(checkpoints[0], tmp_path, hand="body.pt"), "--hand", "body")
    _expect_error(capsys, _convert(checkpoints[0], tmp_path, body="pose_shape_best.pth"), "--body", "hand checkpoint")
    _expect_error(capsys, _convert(checkpoints[0], tmp_path, mean="body.pt"), "--hand-mean")
    assert not (tmp_path / "regressors.json").exists()


def test_truncated_checkpoint_is_an_error(checkpoints, tmp_path, capsys):
    root = checkpoints[0]
    data = (root / "pose_shape_best.pth").read_bytes()
    (tmp_path / "cut.pth").write_bytes(data[: len(data) // 2])
    _expect_error(capsys, _convert(root, tmp_path / "out", hand=str(tmp_path / "cut.pth")), "--hand", "truncated")


def test_missing_and_misshaped_keys_are_errors(checkpoints, tmp_path, capsys):
    root, hand, _ = checkpoints
    state = dict(hand.state_dict())
    del state["main_encoder.layer3.2.bn2.running_var"]
    torch.save(state, tmp_path / "missing.pth")
    _expect_error(capsys, _convert(root, tmp_path / "a", hand=str(tmp_path / "missing.pth")),
                  "missing encoder.layer3.2.bn2.var")
    state = dict(hand.state_dict(), **{"regressor.0.weight": torch.zeros(61, 1000)})
    torch.save(state, tmp_path / "shape.pth")
    _expect_error(capsys, _convert(root, tmp_path / "b", hand=str(tmp_path / "shape.pth")),
                  "regressor.kernel", "(1000, 61)", "(1085, 61)")


def test_load_checks_the_folder(converted, tmp_path):
    with pytest.raises(R.WeightsError, match="convert-frankmocap"):
        R.load(tmp_path)
    for name in ("regressors.json", "body.npz"):
        (tmp_path / name).write_bytes((converted / name).read_bytes())
    (tmp_path / "hand.npz").write_bytes((converted / "hand.npz").read_bytes()[:1000])
    with pytest.raises(R.WeightsError, match="hand.npz"):
        R.load(tmp_path)
