"""A few steps of the synthetic recipe, to check an installation (seconds, any machine).

    python -m train.main --config smoke --workdir /tmp/smoke
"""

from train.configs import TrainConfig


def get_config() -> TrainConfig:
    return TrainConfig(kind="hand", dataset="synthetic_hands", depth=18, image_size=64, batch_size=8,
                       learning_rate=1e-3, num_steps=6, eval_every=3, eval_examples=16, log_every=1,
                       checkpoint_every=3, workers=1)
