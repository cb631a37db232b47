"""The paper's hand module: ResNet-50 on real hand datasets (FreiHAND here; point ``data_dir`` at it).

    python -m train.main --config hand --workdir runs/hand --set data_dir=/data/FreiHAND

Not run in this repository (the datasets are licensed downloads); the synthetic config shows the recipe works.
"""

from train.configs import TrainConfig


def get_config() -> TrainConfig:
    return TrainConfig(kind="hand", dataset="freihand", eval_split="evaluation", depth=50, image_size=224,
                       batch_size=64, learning_rate=1e-4, num_steps=200_000)
