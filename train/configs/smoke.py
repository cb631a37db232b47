"""A few steps of the synthetic recipe (`synthetic` with smaller crops, batches and counts), to check an
installation on any machine.

    python -m train.main --config smoke --workdir /tmp/smoke
"""

from train.configs import TrainConfig, synthetic


def get_config() -> TrainConfig:
    return synthetic.get_config().replace(
        image_size=64, batch_size=8, warmup_steps=0, num_steps=6, time_limit_s=0.0, eval_every=3, eval_examples=16,
        log_every=1, checkpoint_every=3, workers=1)
