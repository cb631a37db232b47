"""ResNet-18/34/50 encoders in torchvision's layout (same module names, so checkpoints map one to one), NHWC.

The encoder ends with global average pooling: ``(N, H, W, 3) -> (N, 512)`` for depth 18/34, ``(N, 2048)`` for 50.
BatchNorm always uses its running statistics (inference); training code switches them with ``nnx`` itself.
"""

import jax
import jax.numpy as jnp
from flax import nnx
from jaxtyping import Array, Float

# depth -> (block kind, blocks per stage)
STAGES = {18: ("basic", (2, 2, 2, 2)), 34: ("basic", (3, 4, 6, 3)), 50: ("bottleneck", (3, 4, 6, 3))}
_EXPANSION = {"basic": 1, "bottleneck": 4}


def feature_width(depth: int) -> int:
    """Channels of the pooled features of a ResNet of ``depth`` (18, 34: 512; 50: 2048)."""
    kind, _ = STAGES[depth]
    return 512 * _EXPANSION[kind]


def _conv(cin, cout, k, stride, dtype, rngs):
    pad = k // 2
    return nnx.Conv(cin, cout, (k, k), (stride, stride), padding=((pad, pad), (pad, pad)), use_bias=False,
                    dtype=dtype, rngs=rngs)


def _bn(c, dtype, rngs):
    return nnx.BatchNorm(c, use_running_average=True, momentum=0.9, epsilon=1e-5, dtype=dtype, rngs=rngs)


class Block(nnx.Module):
    """torchvision's BasicBlock (two 3x3) or Bottleneck (1x1, 3x3 with the stride, 1x1 x4)."""

    def __init__(self, kind: str, cin: int, width: int, stride: int, *, dtype, rngs: nnx.Rngs):
        cout = width * _EXPANSION[kind]
        if kind == "basic":
            convs = [(cin, width, 3, stride), (width, width, 3, 1)]
        else:
            convs = [(cin, width, 1, 1), (width, width, 3, stride), (width, cout, 1, 1)]
        for i, (a, b, k, s) in enumerate(convs, start=1):
            setattr(self, f"conv{i}", _conv(a, b, k, s, dtype, rngs))
            setattr(self, f"bn{i}", _bn(b, dtype, rngs))
        self.num_convs = len(convs)
        needs_projection = stride != 1 or cin != cout
        self.downsample = nnx.data(
            nnx.List([_conv(cin, cout, 1, stride, dtype, rngs), _bn(cout, dtype, rngs)]) if needs_projection else None)

    def __call__(self, x: Float[Array, "N H W C"]) -> Float[Array, "N h w D"]:
        y = x
        for i in range(1, self.num_convs + 1):
            y = getattr(self, f"bn{i}")(getattr(self, f"conv{i}")(y))
            if i < self.num_convs:
                y = jax.nn.relu(y)
        if self.downsample is not None:
            x = self.downsample[1](self.downsample[0](x))
        return jax.nn.relu(y + x)


class ResNet(nnx.Module):
    """conv1 7x7/2, bn1, ReLU, max-pool 3x3/2, layer1..layer4, global average pool (no classifier)."""

    def __init__(self, depth: int = 50, *, dtype=None, rngs: nnx.Rngs):
        if depth not in STAGES:
            raise ValueError(f"depth: expected one of {sorted(STAGES)}, got {depth}")
        kind, counts = STAGES[depth]
        self.conv1 = _conv(3, 64, 7, 2, dtype, rngs)
        self.bn1 = _bn(64, dtype, rngs)
        cin = 64
        for stage, (count, width) in enumerate(zip(counts, (64, 128, 256, 512)), start=1):
            blocks = []
            for i in range(count):
                blocks.append(Block(kind, cin, width, 2 if (i == 0 and stage > 1) else 1, dtype=dtype, rngs=rngs))
                cin = width * _EXPANSION[kind]
            setattr(self, f"layer{stage}", nnx.List(blocks))

    def __call__(self, images: Float[Array, "N H W 3"]) -> Float[Array, "N F"]:
        return jnp.mean(self.stages(self.stem(images)), axis=(1, 2))

    def stem(self, images: Float[Array, "N H W 3"]) -> Float[Array, "N h w 64"]:
        """conv1, bn1, ReLU, max-pool: the input of ``layer1``."""
        x = jax.nn.relu(self.bn1(self.conv1(images)))
        return nnx.max_pool(x, (3, 3), (2, 2), padding=((1, 1), (1, 1)))

    def stages(self, x: Float[Array, "N h w C"], first: int = 1, last: int = 4) -> Float[Array, "N h2 w2 D"]:
        """``layer{first}`` .. ``layer{last}`` on the output of the stem (first 1) or of ``layer{first - 1}``."""
        for stage in range(first, last + 1):
            for block in getattr(self, f"layer{stage}"):
                x = block(x)
        return x
