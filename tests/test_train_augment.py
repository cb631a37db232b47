"""Augmentation and batches: labels follow the pixels (2D dots, 3D joints, orientations), mirroring, the evaluation
crop equals the inference crop, blur kernels, and batches as a pure function of (seed, step)."""

import dataclasses
import itertools

import cv2
import numpy as np
import pytest

from jaxmocap.regressors import crops
from train import augment, batches, blur
from train.datasets.sample import BodySample, HandSample

GEOMETRY_ONLY = dataclasses.replace(augment.AugmentConfig(), channel_gain=0.0, brightness=0.0, contrast=0.0,
                                    blur_prob=0.0)
SMPLX_BODY_NAMES = ["pelvis", "l_hip", "r_hip", "spine1", "l_knee", "r_knee", "spine2", "l_ankle", "r_ankle", "spine3",
                    "l_foot", "r_foot", "neck", "l_collar", "r_collar", "head", "l_shoulder", "r_shoulder", "l_elbow",
                    "r_elbow", "l_wrist", "r_wrist"]
BODY_25_NAMES = ["nose", "neck", "r_shoulder", "r_elbow", "r_wrist", "l_shoulder", "l_elbow", "l_wrist", "mid_hip",
                 "r_hip", "r_knee", "r_ankle", "l_hip", "l_knee", "l_ankle", "r_eye", "l_eye", "r_ear", "l_ear",
                 "l_big_toe", "l_small_toe", "l_heel", "r_big_toe", "r_small_toe", "r_heel"]


def _colours(n, seed=0):
    """``n`` BGR colours with well-separated chromaticities."""
    rng = np.random.default_rng(seed)
    chosen = []
    while len(chosen) < n:
        c = rng.uniform(40, 255, 3)
        if all(np.abs(c / c.sum() - d / d.sum()).max() > 0.06 for d in chosen):
            chosen.append(c)
    return np.array(chosen)


def _dots(points, image_size, colours, sigma=1.5):
    """Gaussian dots centred at ``points`` (corner-origin pixels) on black."""
    width, height = image_size
    ys, xs = np.mgrid[:height, :width] + 0.5
    image = np.zeros((height, width, 3))
    for (x, y), colour in zip(points, colours):
        image += np.exp(-((xs - x) ** 2 + (ys - y) ** 2) / (2 * sigma**2))[..., None] * colour
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


def _grid(box, n, rng):
    """``n`` points on a jittered 5x5 grid inside ``box``."""
    x, y, w, h = box
    gx, gy = np.meshgrid(np.linspace(0.1, 0.9, 5), np.linspace(0.1, 0.9, 5))
    points = np.stack([x + gx.ravel() * w, y + gy.ravel() * h], 1)[:n]
    return points + rng.uniform(-2, 2, points.shape)


def _bgr_0_255(example_image, is_body):
    if is_body:
        return ((example_image * crops.IMAGENET_STD + crops.IMAGENET_MEAN) * 255)[..., ::-1]
    return (example_image * 0.5 + 0.5) * 255


def _found_dots(crop_bgr, colours):
    """(joint index by colour, centroid in corner-origin crop pixels) of each dot wholly inside the crop."""
    intensity = crop_bgr.sum(-1)
    count, labels = cv2.connectedComponents((intensity > 30).astype(np.uint8))
    size = crop_bgr.shape[0]
    found = {}
    chroma = colours / colours.sum(1, keepdims=True)
    for k in range(1, count):
        ys, xs = np.nonzero(labels == k)
        if len(xs) < 3 or xs.min() == 0 or ys.min() == 0 or xs.max() == size - 1 or ys.max() == size - 1:
            continue
        w = intensity[ys, xs]
        colour = (crop_bgr[ys, xs] * w[:, None]).sum(0)
        joint = int(np.argmin(np.abs(chroma - colour / colour.sum()).max(1)))
        found[joint] = np.array([(xs * w).sum() / w.sum() + 0.5, (ys * w).sum() / w.sum() + 0.5])
    return found


def _hand_sample(image, box, joints_2d, joints_3d=None, wrist=None, is_left=False):
    return HandSample(image, np.asarray(box, float), joints_2d, np.full((21, 3), np.nan) if joints_3d is None
                      else joints_3d, np.zeros(3) if wrist is None else wrist, np.full((15, 3), 0.1), np.zeros(10),
                      is_left)


def _body_sample(image, box, joints_2d, joints_3d=None, orient=None, body_pose=None):
    return BodySample(image, np.asarray(box, float), joints_2d, np.full((25, 3), np.nan) if joints_3d is None
                      else joints_3d, np.zeros(3) if orient is None else orient,
                      np.zeros((21, 3)) if body_pose is None else body_pose, np.zeros(10))


def _check_dots(make, size, colours, order, seeds, is_body):
    checked = 0
    for seed in seeds:
        ex = make(np.random.default_rng(seed))
        labels = (ex.joints_2d + 1) * size / 2
        found = _found_dots(_bgr_0_255(ex.image, is_body), colours)
        for joint, label in enumerate(labels):
            source = order[joint]  # the dot this label belongs to
            if np.all((label > 5) & (label < size - 5)):
                assert source in found, f"seed {seed}: dot of joint {source} missing near {label}"
                error = np.abs(found[source] - label).max()
                assert error < 0.5, f"seed {seed}, joint {joint}: dot at {found[source]}, label {label}"
                checked += 1
    assert checked > 0.7 * len(seeds) * len(order)


@pytest.mark.parametrize("is_left", [False, True])
def test_hand_labels_follow_pixels(is_left):
    rng = np.random.default_rng(1)
    box = (70, 60, 110, 120)
    points = _grid(box, 21, rng)
    colours = _colours(21)
    sample = _hand_sample(_dots(points, (256, 256), colours), box, points, is_left=is_left)
    def make(r):
        return augment.hand_example(sample, 128, r, GEOMETRY_ONLY)
    _check_dots(make, 128, colours, np.arange(21), range(25), False)


@pytest.mark.parametrize("flip", [0.0, 1.0])
def test_body_labels_follow_pixels(flip):
    rng = np.random.default_rng(2)
    box = (90, 40, 130, 200)
    points = _grid(box, 25, rng)
    colours = _colours(25)
    sample = _body_sample(_dots(points, (320, 280), colours), box, points)
    config = dataclasses.replace(GEOMETRY_ONLY, flip_prob=flip)
    def make(r):
        return augment.body_example(sample, 128, r, config)
    order = augment.BODY_25_MIRROR if flip else np.arange(25)
    _check_dots(make, 128, colours, order, range(25), True)


def _fit_scale_shift(source, target):
    """Least-squares ``target ~ a source + b`` (scalar a); returns a and the worst residual."""
    design = np.concatenate([source.reshape(-1, 1), np.tile(np.eye(2), (len(source), 1))], 1)
    solution, *_ = np.linalg.lstsq(design, target.reshape(-1), rcond=None)
    return solution[0], np.abs(design @ solution - target.reshape(-1)).max()


def _rotvec_matrix(rotvec):
    return cv2.Rodrigues(np.asarray(rotvec, np.float64))[0]


@pytest.mark.parametrize("is_left", [False, True])
def test_hand_3d_and_orientation_turn_with_the_image(is_left):
    rng = np.random.default_rng(3)
    model_points = rng.normal(0, 0.05, (21, 3))
    wrist = rng.normal(0, 1, 3)
    joints_3d = model_points @ _rotvec_matrix(wrist).T + [0, 0, 0.6]
    joints_2d = joints_3d[:, :2] * 900 + [200, 150]  # orthographic view
    sample = _hand_sample(np.zeros((300, 400, 3), np.uint8), (140, 90, 120, 120), joints_2d, joints_3d, wrist,
                          is_left)
    angles = []
    for seed in range(20):
        ex = augment.hand_example(sample, 128, np.random.default_rng(seed))
        scale, residual = _fit_scale_shift(ex.joints_3d[:, :2], ex.joints_2d)
        assert scale > 0 and residual < 1e-4, (scale, residual)
        mirrored = model_points * ([-1, 1, 1] if is_left else 1)  # the right hand's model points
        np.testing.assert_allclose(ex.joints_3d - ex.joints_3d[:1], (mirrored @ _rotvec_matrix(ex.pose[0]).T)
                                   - (mirrored @ _rotvec_matrix(ex.pose[0]).T)[:1], atol=1e-5)
        np.testing.assert_allclose(ex.pose[1:], 0.1 * np.array([1, -1, -1] if is_left else [1, 1, 1]) + 0 * ex.pose[1:],
                                   atol=1e-7)
        angles.append(np.arctan2(*(ex.joints_3d[1, 1::-1] - ex.joints_3d[0, 1::-1])))
    assert np.ptp(angles) > 0.3  # the rotation was really applied


@pytest.mark.parametrize("flip", [0.0, 1.0])
def test_body_3d_and_pose_mirror_consistently(flip):
    rng = np.random.default_rng(4)
    model_points = rng.normal(0, 0.4, (25, 3))
    orient = rng.normal(0, 1, 3)
    body_pose = rng.normal(0, 0.3, (21, 3))
    joints_3d = model_points @ _rotvec_matrix(orient).T + [0, 0, 3.0]
    sample = _body_sample(np.zeros((300, 400, 3), np.uint8), (120, 40, 150, 220), joints_3d[:, :2] * 200 + [200, 150],
                          joints_3d, orient, body_pose)
    config = dataclasses.replace(augment.AugmentConfig.body(), rotate_prob=1.0, flip_prob=flip)
    for seed in range(10):
        ex = augment.body_example(sample, 96, np.random.default_rng(seed), config)
        scale, residual = _fit_scale_shift(ex.joints_3d[:, :2], ex.joints_2d)
        assert scale > 0 and residual < 1e-4
        order = augment.BODY_25_MIRROR if flip else np.arange(25)
        model = model_points[order] * ([-1, 1, 1] if flip else 1)
        turned = model @ _rotvec_matrix(ex.pose[0]).T
        np.testing.assert_allclose(ex.joints_3d - ex.joints_3d[:1], turned - turned[:1], atol=1e-5)
        expected = body_pose[augment.SMPLX_BODY_MIRROR[1:] - 1] * [1, -1, -1] if flip else body_pose
        np.testing.assert_allclose(ex.pose[1:], expected, atol=1e-6)


def test_mirror_tables_swap_sides_and_are_involutions():
    for table, names in ((augment.SMPLX_BODY_MIRROR, SMPLX_BODY_NAMES), (augment.BODY_25_MIRROR, BODY_25_NAMES)):
        np.testing.assert_array_equal(table[table], np.arange(len(table)))
        swapped = [{"l_": "r_", "r_": "l_"}.get(n[:2], n[:2]) + n[2:] for n in names]
        assert [names[i] for i in table] == swapped


def test_left_hand_is_the_mirrored_right_hand():
    rng = np.random.default_rng(5)
    image = cv2.resize(rng.integers(0, 256, (24, 32, 3), dtype=np.uint8), (320, 240))
    box = np.array([100.0, 60.0, 90.0, 70.0])
    joints_2d, joints_3d = rng.uniform(100, 180, (21, 2)), rng.normal(0, 0.1, (21, 3))
    left = _hand_sample(image, box, joints_2d, joints_3d, rng.normal(0, 1, 3), True)
    right = _hand_sample(image[:, ::-1].copy(), [320 - box[0] - box[2], *box[1:]], joints_2d * [-1, 1] + [320, 0],
                         joints_3d * [-1, 1, 1], left.wrist_rotvec * [1, -1, -1], False)
    right = right._replace(hand_pose=left.hand_pose * [1, -1, -1])
    a, b = augment.hand_example(left, 224), augment.hand_example(right, 224)
    for name in ("joints_2d", "joints_3d", "pose"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), atol=1e-5, err_msg=name)
    assert np.abs(a.image - b.image).max() * 127.5 <= 1.01


def _smooth_image(rng, width, height):
    return cv2.resize(rng.integers(0, 256, (height // 8, width // 8, 3), dtype=np.uint8), (width, height),
                      interpolation=cv2.INTER_CUBIC)


@pytest.mark.parametrize("box, is_left", [((150, 80, 60, 90), False), ((5, 170, 80, 50), False),
                                          ((150, 80, 60, 90), True)])
def test_hand_evaluation_crop_is_the_inference_crop(box, is_left):
    image = _smooth_image(np.random.default_rng(6), 320, 240)
    sample = _hand_sample(image, box, np.zeros((21, 2)), is_left=is_left)
    ours = augment.hand_example(sample, crops.SIZE).image
    window = crops.hand_windows(np.array([box], float), (320, 240))
    reference = np.asarray(crops.normalize_hand(crops.crop(image[None], np.zeros(1, int), window, np.array([is_left])))
                           )[0]
    grey_levels = np.abs(ours - reference) * 127.5
    assert np.mean(grey_levels <= 1.01) > 0.98 and np.median(grey_levels) < 0.5


def test_body_evaluation_crop_is_the_inference_crop():
    image = _smooth_image(np.random.default_rng(7), 320, 240)
    box = (200.0, 30.0, 100.0, 190.0)  # runs off the right edge
    ours = augment.body_example(_body_sample(image, box, np.zeros((25, 2))), crops.SIZE).image
    reference = np.asarray(crops.normalize_body(crops.crop(image[None], np.zeros(1, int),
                                                           crops.body_windows(np.array([box]), (320, 240)))))[0]
    grey_levels = np.abs(ours - reference) * crops.IMAGENET_STD * 255
    assert np.mean(grey_levels <= 1.01) > 0.98


def test_augmentation_changes_colour_and_is_deterministic_per_rng():
    image = _smooth_image(np.random.default_rng(8), 256, 256)
    sample = _hand_sample(image, (80, 80, 100, 100), np.zeros((21, 2)))
    a = augment.hand_example(sample, 64, np.random.default_rng(0))
    b = augment.hand_example(sample, 64, np.random.default_rng(0))
    c = augment.hand_example(sample, 64, np.random.default_rng(1))
    np.testing.assert_array_equal(a.image, b.image)
    assert np.abs(a.image - c.image).mean() > 0.05
    assert a.image.dtype == np.float32 and a.image.shape == (64, 64, 3) and np.all(np.abs(a.image) <= 1)
    black = augment.hand_example(sample._replace(image=np.zeros_like(image)), 64, np.random.default_rng(2))
    np.testing.assert_array_equal(black.image, -1)  # the zero padding stays zero whatever the colour jitter


def test_unknown_labels_are_masked_and_bad_input_rejected():
    sample = _hand_sample(np.zeros((64, 64, 3), np.uint8), (10, 10, 30, 30), np.full((21, 2), np.nan))
    sample = sample._replace(joints_2d=np.where(np.arange(21)[:, None] < 3, np.full((21, 2), 20.0), np.nan))
    ex = augment.hand_example(sample, 32)
    assert ex.joints_2d_mask.tolist() == [True] * 3 + [False] * 18 and np.all(ex.joints_2d[3:] == 0)
    assert not ex.joints_3d_mask and np.all(ex.joints_3d == 0) and ex.pose_mask and ex.betas_mask
    with pytest.raises(ValueError, match="sample.image"):
        augment.hand_example(sample._replace(image=np.zeros((64, 64), np.uint8)), 32)
    with pytest.raises(ValueError, match="sample.joints_2d"):
        augment.hand_example(sample._replace(joints_2d=np.zeros((20, 2))), 32)
    with pytest.raises(ValueError, match="sample.box"):
        augment.body_example(_body_sample(np.zeros((64, 64, 3), np.uint8), (10, 10, 5, 5), np.zeros((25, 2))), 32)


def test_blur_kernels_are_normalised_centred_psfs():
    rng = np.random.default_rng(9)
    for size in (5, 9, 17, 31):
        for _ in range(5):
            kernel = blur.motion_blur_kernel(rng, size, rng.uniform(0.3, 1), anxiety=rng.uniform(0, 0.05))
            assert kernel.shape == (size, size) and np.all(np.isfinite(kernel)) and np.all(kernel >= 0)
            np.testing.assert_allclose(kernel.sum(), 1, atol=1e-9)
            ys, xs = np.mgrid[:size, :size]
            np.testing.assert_allclose([(kernel * xs).sum(), (kernel * ys).sum()], (size - 1) / 2, atol=1e-6)
    line = blur.motion_blur_kernel(np.random.default_rng(0), 21, anxiety=0.0)
    ys, xs = np.nonzero(line > 1e-3)
    spread = np.linalg.svd(np.stack([xs, ys], 1) - [xs.mean(), ys.mean()], compute_uv=False) / np.sqrt(len(xs))
    assert spread[1] < 0.8 < 4 < spread[0]  # a line
    assert np.ptp(xs) + np.ptp(ys) >= 14  # ... about 18 px long
    np.testing.assert_array_equal(blur.motion_blur_kernel(np.random.default_rng(3), 11),
                                  blur.motion_blur_kernel(np.random.default_rng(3), 11))
    with pytest.raises(ValueError, match="size"):
        blur.motion_blur_kernel(rng, 10)


def test_large_kernels_blur_like_a_plain_filter():
    image = np.random.default_rng(12).integers(0, 256, (40, 50, 3), dtype=np.uint8)
    for size in (9, 15, 25):
        kernel = blur.motion_blur_kernel(np.random.default_rng(size), size, anxiety=0.05)
        reference = cv2.filter2D(image.astype(np.float32), -1, kernel.astype(np.float32),
                                 borderType=cv2.BORDER_REPLICATE)
        assert np.abs(blur.blur(image, kernel) - reference).max() <= 0.6


def test_blur_lowers_gradient_energy():
    image = np.random.default_rng(10).integers(0, 256, (96, 96, 3), dtype=np.uint8)
    def energy(im):
        return sum(np.square(np.diff(im.astype(float), axis=a)).mean() for a in (0, 1))
    for seed in range(5):
        kernel = blur.motion_blur_kernel(np.random.default_rng(seed), 11)
        assert energy(blur.blur(image, kernel)) < 0.5 * energy(image)


def _tiny_dataset(n=10):
    rng = np.random.default_rng(11)
    return [_hand_sample(rng.integers(0, 256, (48, 48, 3), dtype=np.uint8), (10, 12, 20, 22),
                         rng.uniform(10, 30, (21, 2)), is_left=bool(i % 2)) for i in range(n)]


def test_batches_are_a_function_of_seed_and_step():
    data = _tiny_dataset()
    run = list(itertools.islice(batches.batches(data, 4, 32, seed=3, workers=2), 5))
    resumed = list(itertools.islice(batches.batches(data, 4, 32, seed=3, start_step=3, workers=1), 2))
    for a, b in zip(run[3:], resumed):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(batches.batch_at(data, 4, 4, 32, seed=3).image, run[4].image)
    assert run[0].image.shape == (4, 32, 32, 3) and run[0].joints_2d_mask.shape == (4, 21)
    other = batches.batch_at(data, 0, 4, 32, seed=4)
    assert not np.array_equal(other.image, run[0].image)


def test_batch_indices_shuffle_each_epoch_and_drop_the_remainder():
    epochs = {}
    for step in range(6):  # 10 samples, batches of 4: 2 steps per epoch
        epoch, indices = batches.batch_indices(10, 4, step, seed=0)
        epochs.setdefault(epoch, []).extend(indices.tolist())
    assert sorted(epochs) == [0, 1, 2]
    assert all(len(set(v)) == 8 for v in epochs.values())
    assert len({tuple(v) for v in epochs.values()}) == 3
    with pytest.raises(ValueError, match="batch_size"):
        batches.batch_indices(3, 4, 0, seed=0)


def test_stack_rejects_mixed_examples():
    data = _tiny_dataset(2)
    hand = augment.hand_example(data[0], 16)
    body = augment.body_example(_body_sample(np.zeros((64, 64, 3), np.uint8), (10, 10, 30, 40), np.zeros((25, 2))), 16)
    assert batches.stack([hand, hand]).pose.shape == (2, 16, 3)
    with pytest.raises(ValueError, match="examples"):
        batches.stack([hand, body])
