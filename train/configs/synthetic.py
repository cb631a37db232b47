"""ResNet-18 hand regressor trained from scratch on the synthetic hands, on a 2-core CPU in 30 minutes.

    python -m train.main --config synthetic --workdir runs/synthetic

Result: see docs/BENCHMARKS.md ("Training").
"""

from train.configs import TrainConfig


def get_config() -> TrainConfig:
    return TrainConfig(kind="hand", dataset="synthetic_hands", depth=18, image_size=96, batch_size=32,
                       learning_rate=1e-3, warmup_steps=200, num_steps=4000, time_limit_s=1800, eval_every=250,
                       eval_examples=500, log_every=25, checkpoint_every=250, workers=2)
