"""ResNet-18 hand regressor trained from scratch on the synthetic hands, on a 2-core CPU within a 30-minute budget
(``time_limit_s``).

    python -m train.main --config synthetic --workdir runs/synthetic

Result (2026-11-22): held-out synthetic hands (1,000, disjoint seeds) after 2,000 steps of 32 crops (80x80, within
the budget): root-aligned MPJPE 31.4 mm against 63.3 mm for the untrained regressor, which predicts the mean pose
(-50.4%); PA-MPJPE 16.2 -> 14.1 mm, 2D error 13.8 -> 4.5 crop px. Curves: docs/training_synthetic.png; the
machine, timings and details in docs/BENCHMARKS.md ("Training").
"""

from train.configs import TrainConfig
from train.datasets.synthetic_poses import HAND_MEAN_ROTVEC


def get_config() -> TrainConfig:
    return TrainConfig(kind="hand", dataset="synthetic_hands", depth=18, image_size=80, batch_size=32,
                       start_wrist_rotvec=tuple(float(v) for v in HAND_MEAN_ROTVEC),
                       learning_rate=1e-3, warmup_steps=100, num_steps=2300, time_limit_s=1780, eval_every=250,
                       eval_examples=500, log_every=25, checkpoint_every=200, workers=2)
