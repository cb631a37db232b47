"""The trainer: steps lower the loss, a resumed run continues bit-identically, a step sharded over 4 devices equals
the single-device step, the curves plot and the exported weights load."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from jaxmocap.regressors import load_network
from train import configs
from train.batches import batch_at
from train.datasets.synthetic import SyntheticHands
from train.train import create, jitted_train_step, train_and_evaluate

SMOKE = configs.get("smoke").replace(image_size=32, batch_size=4, num_steps=4, eval_every=2, eval_examples=4,
                                     checkpoint_every=2, log_every=1, workers=1)


@pytest.fixture(scope="module")
def body_model():
    from conftest import load
    from smplx_jax.default_model import default_model_path
    return load(default_model_path().parent.parent)


def test_steps_lower_the_loss_on_a_fixed_batch(body_model):
    config = SMOKE.replace(learning_rate=1e-3, num_steps=100)
    setup, constants, state = create(config, body_model)
    batch = batch_at(SyntheticHands(8, seed=5, image_size=64), 0, 8, config.image_size, seed=0, augment=False)
    totals = []
    for _ in range(12):
        state, terms = jitted_train_step(setup, constants, state, batch)
        totals.append(float(terms["total"]))
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
    assert [r["step"] for r in rows] == [0, 1, 2, 3, 4]  # the interrupted run's rows kept, none twice
    assert (tmp_path / "resumed" / "curves.png").stat().st_size > 1000
    network = load_network(tmp_path / "resumed" / "weights", "hand")
    assert network.config.depth == 18


SHARDED = textwrap.dedent("""
    import jax, numpy as np
    import smplx_jax
    from train import configs
    from train.batches import batch_at
    from train.datasets.synthetic import SyntheticHands
    from train.train import create, data_parallel, global_batch, jitted_train_step

    assert jax.device_count() == 4
    config = configs.get("smoke").replace(image_size=32, batch_size=8)
    model = smplx_jax.load_model(smplx_jax.default_model_path())
    setup, constants, state = create(config, model)
    batch = batch_at(SyntheticHands(8, seed=5, image_size=64), 0, 8, 32, seed=0)
    copy = lambda tree: jax.tree.map(lambda a: a.copy(), tree)  # the step donates (deletes) the state it gets
    shardings = data_parallel()
    sharded_batch = global_batch(shardings, batch)
    assert len(sharded_batch.image.sharding.device_set) == 4
    sharded, sharded_terms = jitted_train_step(setup, jax.device_put(constants, shardings.replicated),
                                               jax.device_put(copy(state), shardings.replicated), sharded_batch)
    one = jax.devices()[0]
    single, single_terms = jitted_train_step(setup, jax.device_put(constants, one), jax.device_put(state, one),
                                             jax.device_put(batch, one))
    leaves = lambda s: [np.asarray(a) for a in jax.tree.leaves(jax.device_get((s.params, s.batch_stats)))]
    gap = max(float(np.max(np.abs(a - b)) / (np.max(np.abs(b)) + 1e-12)) for a, b in
              zip(leaves(sharded), leaves(single)))
    loss_gap = abs(float(sharded_terms["total"]) - float(single_terms["total"])) / float(single_terms["total"])
    print("relative parameter gap", gap, "loss gap", loss_gap)
    assert gap < 1e-4 and loss_gap < 1e-5
""")


def test_sharded_step_equals_single_device_step():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", SHARDED], capture_output=True, text=True, env=env, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    print(proc.stdout)
