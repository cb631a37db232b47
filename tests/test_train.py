"""The trainer: steps lower the loss, a resumed run continues bit-identically, a step sharded over 4 devices equals
the single-device step, the curves plot and the exported weights load."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import numpy as np
import pytest

from conftest import with_four_cpu_devices
from jaxmocap.regressors import load_network
from train import configs
from train.batches import batch_at
from train.datasets.synthetic import SyntheticHands
from train.train import create, data_parallel, global_batch, jitted_train_step, train_and_evaluate

# one config for every test here, so that they share one compiled training step
SMOKE = configs.get("smoke").replace(image_size=32, batch_size=8, learning_rate=1e-3, num_steps=12, eval_every=4,
                                     eval_examples=8, checkpoint_every=4, log_every=1, workers=1)


@pytest.fixture(scope="module")
def body_model():
    from conftest import load
    from smplx_jax.default_model import default_model_path
    return load(default_model_path().parent.parent)


def fixed_batch():
    return batch_at(SyntheticHands(8, seed=5, image_size=64), 0, 8, SMOKE.image_size, seed=0, augment=False)


def steps_on_one_batch(body_model, count: int):
    """``count`` steps on `fixed_batch`, placed as `train_and_evaluate` places its batches: the state after them and
    the total loss of each."""
    setup, constants, state = create(SMOKE, body_model)
    shardings = data_parallel()
    state, batch = jax.device_put(state, shardings.replicated), global_batch(shardings, fixed_batch())
    totals = []
    for _ in range(count):
        state, terms = jitted_train_step(setup, constants, state, batch)
        totals.append(float(terms["total"]))
    return state, totals


def compared(state) -> list[np.ndarray]:
    """What the sharded step must equal: the weights, BatchNorm's statistics and Adam's moments, as NumPy arrays."""
    return [np.asarray(a) for a in jax.tree.leaves(jax.device_get((state.params, state.batch_stats, state.opt_state)))]


def test_steps_lower_the_loss_on_a_fixed_batch(body_model):
    state, totals = steps_on_one_batch(body_model, 12)
    assert all(np.isfinite(totals)) and int(state.step) == 12
    assert min(totals[-3:]) < 0.5 * totals[0], totals


def test_resume_is_bit_identical(tmp_path, body_model):
    straight = train_and_evaluate(SMOKE, tmp_path / "straight")
    interrupted = train_and_evaluate(SMOKE.replace(time_limit_s=1e-9), tmp_path / "resumed")
    assert interrupted["step"] == 1  # stopped (and checkpointed) after its first step
    resumed = train_and_evaluate(SMOKE, tmp_path / "resumed")
    assert straight["step"] == resumed["step"] == SMOKE.num_steps
    a = np.load(tmp_path / "straight" / "weights" / "hand.npz")
    b = np.load(tmp_path / "resumed" / "weights" / "hand.npz")
    assert a.files == b.files and all(np.array_equal(a[k], b[k]) for k in a.files)
    assert straight["eval"] == resumed["eval"]
    rows = [json.loads(line) for line in (tmp_path / "resumed" / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == list(range(SMOKE.num_steps + 1))  # the interrupted run's rows kept, none twice
    assert (tmp_path / "resumed" / "curves.png").stat().st_size > 1000
    network = load_network(tmp_path / "resumed" / "weights", "hand")
    assert network.config.depth == 18


SHARDED = textwrap.dedent("""
    import sys
    import jax, numpy as np
    import smplx_jax
    from test_train import SMOKE, compared, fixed_batch
    from train.train import create, data_parallel, global_batch, jitted_train_step

    assert jax.device_count() == 4
    setup, constants, state = create(SMOKE, smplx_jax.load_model(smplx_jax.default_model_path()))
    shardings = data_parallel()
    batch = global_batch(shardings, fixed_batch())
    assert len(batch.image.sharding.device_set) == 4
    state, terms = jitted_train_step(setup, jax.device_put(constants, shardings.replicated),
                                     jax.device_put(state, shardings.replicated), batch)
    np.savez(sys.argv[1], total=float(terms["total"]), *compared(state))
""")


def test_sharded_step_equals_single_device_step(tmp_path, body_model):
    """A step with the batch split over 4 devices (a subprocess) equals the step on this process's one device: the
    weights, BatchNorm's statistics and Adam's moments (the schedule's first step has a learning rate of 0, so the
    moments, which hold the gradient, are what shows it right)."""
    single, totals = steps_on_one_batch(body_model, 1)
    env = with_four_cpu_devices(
        PYTHONPATH=os.pathsep.join(filter(None, [str(Path(__file__).parent), os.environ.get("PYTHONPATH")])))
    proc = subprocess.run([sys.executable, "-c", SHARDED, str(tmp_path / "sharded.npz")], capture_output=True,
                          text=True, env=env, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    sharded = np.load(tmp_path / "sharded.npz")
    leaves = compared(single)
    assert len(sharded.files) == len(leaves) + 1
    gap = max(float(np.max(np.abs(sharded[f"arr_{i}"] - b)) / (np.max(np.abs(b)) + 1e-12))
              for i, b in enumerate(leaves))
    loss_gap = abs(float(sharded["total"]) - totals[-1]) / totals[-1]
    print("relative gap of the weights, statistics and moments", gap, "of the loss", loss_gap)
    assert gap < 1e-4 and loss_gap < 1e-5
