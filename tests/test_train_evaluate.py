"""train.evaluate: the metric table end to end on synthetic hands with random weights, and its metrics by hand."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.io
from flax import nnx

import smplx_jax
from jaxmocap.regressors import HandConfig, HandRegressor, crops
from jaxmocap.regressors.weights import build, load_network, save, variable_names
from train.augment import hand_example
from train.datasets import open_dataset
from train.evaluate import LABELS, evaluate_hands, format_table, hand_metrics, main, pixels_per_crop_unit
from train.losses import hand_crop_joints, right_hand_joints


@pytest.fixture(scope="module")
def weights_dir(tmp_path_factory):
    """A random ResNet-18 hand network (drawn in numpy: seconds faster than flax's initialisers)."""
    config = HandConfig(depth=18)
    rng = np.random.default_rng(0)
    shapes = variable_names(nnx.eval_shape(lambda: HandRegressor(config, rngs=nnx.Rngs(0))))
    arrays = {name: np.ones(shape) if name.endswith(("var", "scale")) else rng.normal(scale=0.02, size=shape)
              for name, shape in shapes.items()}
    arrays["mean_params"][:] = np.eye(61)[0] * 5.0  # FrankMocap's initial camera scale
    network = build("hand", config, arrays, "random")
    directory = tmp_path_factory.mktemp("weights")
    save(directory, {"hand": network}, {"hand": "random"})
    return directory


def test_end_to_end_on_synthetic_hands(weights_dir, tmp_path, capsys):
    out = tmp_path / "results.json"
    code = main(["--dataset", "synthetic_hands", "--data-dir", str(tmp_path), "--weights", str(weights_dir),
                 "--limit", "3", "--batch-size", "4", "--json", str(out)])
    assert code == 0
    table = capsys.readouterr().out
    assert "synthetic_hands 3D AUC 20-50mm" in table and "synthetic_hands 2D AUC 0-30px" in table
    assert str(weights_dir) in table.splitlines()[2]
    saved = json.loads(out.read_text())
    assert saved["split"] == "test" and saved["limit"] == 3
    metrics = saved["results"][str(weights_dir)]["synthetic_hands"]
    assert metrics["count"] == 3 and set(metrics) == {"count", *LABELS}
    assert metrics["mpjpe_mm"] >= metrics["pa_mpjpe_mm"] > 0  # an untrained network is not perfect
    # the same numbers from the network's own predictions on those samples, computed here from the definitions
    samples = open_dataset("synthetic_hands", tmp_path, "test")
    examples = [hand_example(samples[i], crops.SIZE) for i in range(3)]
    model = smplx_jax.load_model(smplx_jax.default_model_path())
    raw = load_network(weights_dir, "hand")(jnp.asarray(np.stack([e.image for e in examples]), jnp.float32))
    joints = np.asarray(jax.vmap(right_hand_joints, in_axes=(None, None, 0))(
        model, smplx_jax.hand_model(model, "right"), raw)) * 1000
    labels = np.stack([e.joints_3d for e in examples]) * 1000
    errors_3d = np.linalg.norm((joints - joints[:, :1]) - (labels - labels[:, :1]), axis=-1)
    crop = np.asarray(jax.vmap(hand_crop_joints)(jnp.asarray(joints / 1000), raw[:, :3]))
    sides = np.array([pixels_per_crop_unit(samples[i]) for i in range(3)])[:, None]
    errors_2d = np.linalg.norm(crop - np.stack([e.joints_2d for e in examples]), axis=-1) * sides

    def auc(errors, lo, hi):  # the PCK curve's area on 20 thresholds, normalised
        thresholds = np.linspace(lo, hi, 20)
        return np.trapezoid([(errors <= t).mean() for t in thresholds], thresholds) / (hi - lo)

    expected = dict(mpjpe_mm=errors_3d.mean(), auc_3d_20_50mm=auc(errors_3d, 20, 50),
                    auc_2d_0_30px=auc(errors_2d, 0, 30))
    assert {k: metrics[k] for k in expected} == pytest.approx(expected, rel=1e-3, abs=1e-6)
    assert 0 < expected["auc_3d_20_50mm"] < 1 and errors_2d.min() > 30  # (the random network's 2D: all beyond)


def test_body_datasets_are_refused(weights_dir, tmp_path, capsys):
    code = main(["--dataset", "synthetic_bodies", "--data-dir", str(tmp_path), "--weights", str(weights_dir)])
    assert code == 2
    assert "synthetic_bodies" in capsys.readouterr().err


@pytest.fixture(scope="module")
def labels():
    rng = np.random.default_rng(0)
    gt_3d = rng.normal(scale=40.0, size=(5, 21, 3))
    gt_2d = rng.uniform(0, 200, size=(5, 21, 2))
    mask_2d = rng.random((5, 21)) < 0.8
    return gt_3d, np.ones((5, 21), bool), gt_2d, mask_2d


def test_a_perfect_predictor(labels):
    gt_3d, mask_3d, gt_2d, mask_2d = labels
    metrics = hand_metrics(gt_3d, gt_3d, mask_3d, gt_2d, gt_2d, mask_2d)
    assert metrics == pytest.approx(dict(auc_3d_20_50mm=1.0, mpjpe_mm=0.0, pa_mpjpe_mm=0.0, auc_2d_0_30px=1.0))


def test_metrics_by_hand(labels):
    gt_3d, mask_3d, gt_2d, mask_2d = labels
    moved = gt_3d + [100.0, -50.0, 20.0]  # a translation: nothing once root-aligned
    bigger = (gt_3d - gt_3d[:, :1]) * 1.1 + gt_3d[:, :1]  # a scaling about the root: PA-MPJPE 0
    offset_2d = gt_2d + [12.0, 16.0]  # 20 px everywhere: PCK 0 below 20 px, 1 from there on
    metrics = hand_metrics(moved, gt_3d, mask_3d, offset_2d, gt_2d, mask_2d)
    assert metrics["mpjpe_mm"] == pytest.approx(0.0, abs=1e-9)
    thresholds = np.linspace(0, 30, 20)
    first = np.argmax(thresholds >= 20 - 1e-9)
    expected = (0.5 * (thresholds[first] - thresholds[first - 1]) + 30 - thresholds[first]) / 30
    assert metrics["auc_2d_0_30px"] == pytest.approx(expected)
    scaled = hand_metrics(bigger, gt_3d, mask_3d, gt_2d, gt_2d, np.zeros((5, 21), bool))
    assert "auc_2d_0_30px" not in scaled
    assert scaled["pa_mpjpe_mm"] == pytest.approx(0.0, abs=1e-9)
    root_relative = np.linalg.norm(gt_3d - gt_3d[:, :1], axis=-1)
    assert scaled["mpjpe_mm"] == pytest.approx(np.mean(0.1 * root_relative))


def test_format_table_leaves_missing_metrics_blank():
    results = {"a": {"stb": dict(auc_3d_20_50mm=0.99, mpjpe_mm=9.04, pa_mpjpe_mm=7.0, count=3)},
               "b": {"stb": dict(auc_3d_20_50mm=0.5), "mpii_nzsl": dict(auc_2d_0_30px=0.655)}}
    lines = format_table(results).splitlines()
    assert lines[0].split("  ")[0].strip() == "weights" and "mpii_nzsl 2D AUC 0-30px" in lines[0]
    assert lines[2].split() == ["a", "0.990", "9.0", "7.0", "-"]
    assert lines[3].split() == ["b", "0.500", "-", "-", "0.655"]


class _Fixed(nnx.Module):
    """A network that outputs given raw parameters whatever the images (an oracle from the labels)."""

    def __init__(self, raw):
        self.raw = nnx.Variable(jnp.asarray(raw, jnp.float32))

    def __call__(self, images):
        return self.raw[...]


def test_the_labels_own_parameters_score_near_perfectly():
    """Raw parameters made from each example's pose, betas and a camera fitted to its 2D labels: the evaluation's
    frames (wrist-aligned 3D, mirrored left hands, crop to image pixels) agree with the labels'."""
    model = smplx_jax.load_model(smplx_jax.default_model_path())
    right_hand = smplx_jax.hand_model(model, "right")
    dataset = open_dataset("synthetic_hands", "unused", "test")
    left = [dataset.params(i).is_left for i in range(32)]
    samples = [dataset[int(i)] for i in np.concatenate([np.flatnonzero(left)[:2], np.flatnonzero(~np.array(left))[:2]])]
    raws = []
    for example in (hand_example(s, crops.SIZE) for s in samples):
        pose = np.concatenate([example.pose[:1], smplx_jax.hand_pose_to_relative(model, example.pose[1:], "right")])
        raw = np.concatenate([[1.0, 0.0, 0.0], pose.ravel(), example.betas])
        joints = np.asarray(jax.jit(right_hand_joints)(model, right_hand, jnp.asarray(raw, jnp.float32)))
        xy = joints[:, :2] - joints[5, :2]
        design = np.zeros((42, 3))
        design[:, 0], design[0::2, 1], design[1::2, 2] = xy.ravel(), 1, 1
        s, u, v = np.linalg.lstsq(design, example.joints_2d.ravel(), rcond=None)[0]
        raws.append(np.concatenate([[s, u / s, v / s], raw[3:]]))
    metrics = evaluate_hands(_Fixed(np.stack(raws)), model, right_hand, samples, batch_size=4)
    assert metrics["mpjpe_mm"] < 0.5 and metrics["auc_3d_20_50mm"] == 1.0
    assert metrics["auc_2d_0_30px"] > 0.8  # weak perspective against the pinhole camera that rendered them


def test_pixels_per_crop_unit_matches_the_crop():
    """Distances between 2D labels in the image and in the evaluation crop differ by exactly that factor."""
    dataset = open_dataset("synthetic_hands", "unused", "test")
    for sample in (dataset[0], dataset[7]):
        example = hand_example(sample, crops.SIZE)
        image_spread = np.linalg.norm(sample.joints_2d - sample.joints_2d.mean(0))
        crop_spread = np.linalg.norm(example.joints_2d - example.joints_2d.mean(0))
        assert pixels_per_crop_unit(sample) == pytest.approx(image_spread / crop_spread, rel=1e-4)


def test_table_from_dataset_directories(weights_dir, tmp_path, capsys):
    """STB (3D) and MPII+NZSL (2D) folders in their real layouts give the paper's Table 2 columns."""
    from test_train_hand_datasets import projected, right_hand, stb_hand_para, write_image

    stb_root, mpii_root = tmp_path / "stb", tmp_path / "mpii"
    (stb_root / "labels").mkdir(parents=True)
    left = right_hand() * [-1, 1, 1]
    for seq in ("B1Counting", "B1Random"):
        scipy.io.savemat(stb_root / "labels" / f"{seq}_SK.mat", {"handPara": stb_hand_para([left, left])})
        for i in range(2):
            write_image(stb_root / "images" / seq / f"SK_color_{i}.png", 480, 640)
    folder = mpii_root / "hand_labels" / "manual_test"
    write_image(folder / "a_r.jpg", 48, 64)
    label = {"hand_pts": np.c_[projected(right_hand()), np.ones(21)].tolist(), "is_left": 0}
    (folder / "a_r.json").write_text(json.dumps(label))
    code = main(["--dataset", "stb,mpii_nzsl", "--data-dir", f"{stb_root},{mpii_root}", "--weights",
                 str(weights_dir), "--batch-size", "4"])
    assert code == 0, capsys.readouterr().err
    header, _, row = capsys.readouterr().out.splitlines()[:3]
    assert "stb 3D AUC 20-50mm" in header and "stb MPJPE mm" in header and "mpii_nzsl 2D AUC 0-30px" in header
    assert "mpii_nzsl 3D" not in header  # 2D labels only
    assert all(np.isfinite(float(cell)) for cell in row.split()[1:])
