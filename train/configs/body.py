"""The body module the SPIN way: ResNet-50 on COCO with EFT pseudo ground truth.

    python -m train.main --config body --workdir runs/body --set data_dir=/data/coco

Not run in this repository (COCO images and EFT fits are downloads); ``--config smoke --set kind=body
--set dataset=synthetic_bodies`` exercises the same code on rendered bodies.
"""

from train.configs import TrainConfig


def get_config() -> TrainConfig:
    return TrainConfig(kind="body", dataset="coco_eft", eval_dataset="synthetic_bodies", depth=50, image_size=224,
                       batch_size=64, learning_rate=5e-5, num_steps=200_000)
