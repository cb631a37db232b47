"""FrankMocap's two regressors as plain PyTorch modules (torchvision is not needed), with the module names of
the released checkpoints, so ``state_dict()`` has their keys. Used only to check our networks and importer."""

import pickle
from pathlib import Path

import numpy as np
import torch
from torch import nn


class Bottleneck(nn.Module):
    expansion = 4

    def __init__(self, cin, width, stride):
        super().__init__()
        cout = width * 4
        self.conv1 = nn.Conv2d(cin, width, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(width)
        self.conv2 = nn.Conv2d(width, width, 3, stride, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(width)
        self.conv3 = nn.Conv2d(width, cout, 1, bias=False)
        self.bn3 = nn.BatchNorm2d(cout)
        self.relu = nn.ReLU()
        self.downsample = None
        if stride != 1 or cin != cout:
            self.downsample = nn.Sequential(nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout))

    def forward(self, x):
        y = self.relu(self.bn1(self.conv1(x)))
        y = self.relu(self.bn2(self.conv2(y)))
        y = self.bn3(self.conv3(y))
        return self.relu(y + (x if self.downsample is None else self.downsample(x)))


class ResNet50(nn.Module):
    """torchvision's resnet50 without avgpool/fc modules; ``features`` pools globally."""

    def __init__(self):
        super().__init__()
        self.conv1 = nn.Conv2d(3, 64, 7, 2, 3, bias=False)
        self.bn1 = nn.BatchNorm2d(64)
        self.relu = nn.ReLU()
        self.maxpool = nn.MaxPool2d(3, 2, 1)
        cin = 64
        for stage, (count, width) in enumerate(zip((3, 4, 6, 3), (64, 128, 256, 512)), start=1):
            blocks = []
            for i in range(count):
                blocks.append(Bottleneck(cin, width, 2 if (i == 0 and stage > 1) else 1))
                cin = width * 4
            setattr(self, f"layer{stage}", nn.Sequential(*blocks))

    def features(self, x):
        x = self.maxpool(self.relu(self.bn1(self.conv1(x))))
        x = self.layer4(self.layer3(self.layer2(self.layer1(x))))
        return x.mean(dim=(2, 3))


class HandEncoder(ResNet50):
    def __init__(self):
        super().__init__()
        self.fc1 = nn.Linear(2048, 1024)


class HandNet(nn.Module):
    """FrankMocap's hand module; input NCHW, output (N, 61)."""

    def __init__(self, mean_params):
        super().__init__()
        self.main_encoder = HandEncoder()
        self.feat_encoder = nn.Sequential(nn.ReLU(), nn.Linear(1024, 1024), nn.ReLU())
        self.regressor = nn.Sequential(nn.Linear(1024 + 61, 61))
        self.mean_params = torch.as_tensor(mean_params, dtype=torch.float32)  # not in the checkpoint

    def forward(self, x):
        feat = self.feat_encoder(torch.relu(self.main_encoder.fc1(self.main_encoder.features(x))))
        params = self.mean_params.expand(x.shape[0], -1)
        for _ in range(3):
            params = params + self.regressor(torch.cat([feat, params], 1))
        return params


def rot6d_to_rotmat(x):
    x = x.reshape(-1, 3, 2)
    a1, a2 = x[:, :, 0], x[:, :, 1]
    b1 = nn.functional.normalize(a1)
    b2 = nn.functional.normalize(a2 - torch.einsum("bi,bi->b", b1, a2).unsqueeze(-1) * b1)
    return torch.stack((b1, b2, torch.cross(b1, b2, dim=1)), dim=-1)


class HMR(ResNet50):
    """SPIN's HMR; input NCHW, output (rotmats (N,24,3,3), betas (N,10), camera (N,3))."""

    def __init__(self, mean_pose, mean_shape, mean_cam):
        super().__init__()
        self.fc1 = nn.Linear(2048 + 144 + 13, 1024)
        self.drop1 = nn.Dropout()
        self.fc2 = nn.Linear(1024, 1024)
        self.drop2 = nn.Dropout()
        self.decpose = nn.Linear(1024, 144)
        self.decshape = nn.Linear(1024, 10)
        self.deccam = nn.Linear(1024, 3)
        self.register_buffer("init_pose", torch.as_tensor(mean_pose, dtype=torch.float32)[None])
        self.register_buffer("init_shape", torch.as_tensor(mean_shape, dtype=torch.float32)[None])
        self.register_buffer("init_cam", torch.as_tensor(mean_cam, dtype=torch.float32)[None])

    def forward(self, x):
        xf = self.features(x)
        n = x.shape[0]
        pose, shape, cam = self.init_pose.expand(n, -1), self.init_shape.expand(n, -1), self.init_cam.expand(n, -1)
        for _ in range(3):
            xc = self.drop2(self.fc2(self.drop1(self.fc1(torch.cat([xf, pose, shape, cam], 1)))))
            pose, shape, cam = self.decpose(xc) + pose, self.decshape(xc) + shape, self.deccam(xc) + cam
        return rot6d_to_rotmat(pose).reshape(n, 24, 3, 3), shape, cam


def randomize(module: nn.Module, seed: int) -> nn.Module:
    """Random weights with the scale of a trained network, and non-trivial BatchNorm statistics; eval mode."""
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for m in module.modules():
            if isinstance(m, nn.BatchNorm2d):
                c = m.num_features
                m.weight.copy_(0.5 + 0.5 * torch.rand(c, generator=gen))
                m.bias.copy_(0.1 * torch.randn(c, generator=gen))
                m.running_mean.copy_(0.1 * torch.randn(c, generator=gen))
                m.running_var.copy_(0.5 + torch.rand(c, generator=gen))
                m.num_batches_tracked.fill_(1000)
            elif isinstance(m, (nn.Conv2d, nn.Linear)):
                fan_in = m.weight[0].numel()
                m.weight.copy_(torch.randn(m.weight.shape, generator=gen) * np.sqrt(1.0 / fan_in))
                if m.bias is not None:
                    m.bias.copy_(0.01 * torch.randn(m.bias.shape, generator=gen))
    return module.eval()


def body_crop(img, box_xywh, res=224):
    """SPIN/FrankMocap's body crop, transcribed: centre/scale, corners through the inverted crop transform and
    truncated to int, zero canvas, paste, cv2.resize. Returns (crop uint8, ratio, top-left) or None."""
    import cv2

    box = np.asarray(box_xywh, np.float64)
    center, h = box[:2] + 0.5 * box[2:], 1.2 * max(box[2:])
    t = np.array([[res / h, 0, res * (-center[0] / h + 0.5)], [0, res / h, res * (-center[1] / h + 0.5)], [0, 0, 1]])
    inv = np.linalg.inv(t)
    ul = (inv @ [0, 0, 1])[:2].astype(int)
    br = (inv @ [res, res, 1])[:2].astype(int)
    shape = [br[1] - ul[1], br[0] - ul[0]]
    if shape[0] < 20 or shape[1] < 20:
        return None
    canvas = np.zeros(shape + [3], np.uint8)
    new_x = max(0, -ul[0]), min(br[0], img.shape[1]) - ul[0]
    new_y = max(0, -ul[1]), min(br[1], img.shape[0]) - ul[1]
    old_x = max(0, ul[0]), min(img.shape[1], br[0])
    old_y = max(0, ul[1]), min(img.shape[0], br[1])
    if min(new_x + new_y) < 0:
        return None
    canvas[new_y[0]:new_y[1], new_x[0]:new_x[1]] = img[old_y[0]:old_y[1], old_x[0]:old_x[1]]
    return cv2.resize(canvas, (res, res)), res / shape[0], ul


def hand_crop(img, box_xywh, res=224):
    """FrankMocap's hand crop (``__pad_and_resize`` with the 30% margin), transcribed."""
    import cv2

    height, width = img.shape[:2]
    min_x, min_y = np.asarray(box_xywh[:2]).astype(np.int32)
    w, h = np.asarray(box_xywh[2:]).astype(np.int32)
    max_x, max_y = min_x + w, min_y + h
    if w > h:
        margin = (w - h) // 2
        min_y, max_y = max(min_y - margin, 0), min(max_y + margin, height)
    else:
        margin = (h - w) // 2
        min_x, max_x = max(min_x - margin, 0), min(max_x + margin, width)
    margin = int(0.3 * (max_y - min_y))
    min_y, max_y = max(min_y - margin, 0), min(max_y + margin, height)
    min_x, max_x = max(min_x - margin, 0), min(max_x + margin, width)
    if max_x <= min_x or max_y <= min_y:
        return None  # the box lies outside the image: FrankMocap fails here
    size = max(max_x - min_x, max_y - min_y)
    canvas = np.zeros((size, size, 3), np.uint8)
    canvas[:max_y - min_y, :max_x - min_x] = img[min_y:max_y, min_x:max_x]
    return cv2.resize(canvas, (res, res)), res / size, np.array([min_x, min_y])


def write_checkpoints(root, seed: int = 0):
    """Random reference networks saved as FrankMocap ships them: ``pose_shape_best.pth`` (hand state_dict),
    ``body.pt`` (``{'model': state_dict}``) and ``mean_mano_params.pkl``; returns the (hand, body) modules."""
    root = Path(root)
    rng = np.random.default_rng(seed)
    mean_pose = rng.normal(0, 0.3, 48).astype(np.float32)
    with open(root / "mean_mano_params.pkl", "wb") as f:
        pickle.dump({"mean_pose": mean_pose, "mean_betas": np.zeros(10, np.float32)}, f)
    mean = np.concatenate([[5, 0, 0, 0, 0, 0], mean_pose[3:], np.zeros(10)]).astype(np.float32)
    hand = randomize(HandNet(mean), seed=seed + 1)
    body = randomize(HMR(np.tile([1.0, 0, 0, 1, 0, 0], 24) + rng.normal(0, 0.1, 144),
                         rng.normal(0, 1, 10), [0.9, 0.0, 0.0]), seed=seed + 2)
    torch.save(hand.state_dict(), root / "pose_shape_best.pth")
    torch.save({"model": body.state_dict(), "epoch": 7}, root / "body.pt")
    return hand, body
