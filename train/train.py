"""Training and evaluation of the hand or body regressor: pure `train_step` / `eval_step`, data-parallel over all
JAX devices (and hosts), orbax checkpoints, and a resumable `train_and_evaluate(config, workdir)`.

A run is a function of its config: the batch of step ``s`` depends only on (seed, s), so a run interrupted and
resumed from its last checkpoint continues bit-identically.
"""

import functools
import json
import time
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
import orbax.checkpoint as ocp
from flax import nnx
from jax.sharding import Mesh, NamedSharding, PartitionSpec

import smplx_jax
from jaxmocap.regressors import BodyConfig, BodyRegressor, HandConfig, HandRegressor, initialised
from jaxmocap.regressors.hand import CAMERA
from jaxmocap.regressors.weights import save as save_weights
from train import losses, metrics, plot
from train.augment import body_example, hand_example
from train.batches import batches, stack
from train.configs import TrainConfig
from train.datasets import open_dataset

HAND_START_CAMERA = 5.0  # FrankMocap's hand regressor starts from cam [5, 0, 0] and the mean hand
BODY_START_CAMERA = 0.9  # SPIN's mean camera scale
ROOT = {"hand": 0, "body": 8}  # wrist; BODY_25 mid-hip


class TrainState(NamedTuple):
    step: jax.Array
    params: nnx.State  # trained
    batch_stats: nnx.State  # BatchNorm running statistics
    opt_state: optax.OptState


class Setup(NamedTuple):
    """The fixed, hashable part of a run (static under jit)."""

    kind: str
    graphdef: nnx.GraphDef
    optimizer: optax.GradientTransformation


class Constants(NamedTuple):
    """Arrays a step reads but never changes."""

    buffers: nnx.State  # the regressor's start vectors
    body_model: smplx_jax.BodyModel
    right_hand: smplx_jax.HandModel


def create_network(config: TrainConfig) -> nnx.Module:
    """A freshly initialised regressor whose iterations start from the mean (FrankMocap / SPIN), its output layers
    initialised small (HMR's Xavier gain 0.01) so the first steps stay near the mean."""
    return initialised(functools.partial(_new_network, config))


def _new_network(config: TrainConfig) -> nnx.Module:
    rngs = nnx.Rngs(config.seed)
    if config.kind == "hand":
        network = HandRegressor(HandConfig(depth=config.depth), rngs=rngs)
        start = jnp.zeros(61).at[CAMERA].set(jnp.array([HAND_START_CAMERA, 0.0, 0.0]))
        network.mean_params[...] = start.at[3:6].set(jnp.array(config.start_wrist_rotvec))
        outputs = [network.regressor]
    else:
        network = BodyRegressor(BodyConfig(depth=config.depth), rngs=rngs)
        identity_6d = jnp.array([1.0, 0.0, 0.0, 1.0, 0.0, 0.0])  # rows of [[1, 0], [0, 1], [0, 0]]
        upright_6d = jnp.array([1.0, 0.0, 0.0, -1.0, 0.0, 0.0])  # 180 degrees about x: y up -> image y down
        network.init_pose[...] = jnp.concatenate([upright_6d, jnp.tile(identity_6d, 23)])
        network.init_cam[...] = jnp.array([BODY_START_CAMERA, 0.0, 0.0])
        outputs = [network.decpose, network.decshape, network.deccam]
    for layer in outputs:
        layer.kernel[...] = 0.01 * nnx.initializers.xavier_uniform()(rngs.params(), layer.kernel.shape)
    return network


@functools.lru_cache
def optimizer(learning_rate: float, warmup_steps: int, num_steps: int, clip_norm: float):
    """Adam with linear warm-up and cosine decay, gradients clipped; one object per setting, so compiled steps
    are shared by runs with the same config."""
    schedule = optax.warmup_cosine_decay_schedule(0.0, learning_rate, max(warmup_steps, 1),
                                                  max(num_steps, warmup_steps + 1))
    return optax.chain(optax.clip_by_global_norm(clip_norm), optax.adam(schedule))


def create(config: TrainConfig, body_model: smplx_jax.BodyModel) -> tuple[Setup, Constants, TrainState]:
    graphdef, params, batch_stats, buffers = nnx.split(create_network(config), nnx.Param, nnx.BatchStat, ...)
    tx = optimizer(config.learning_rate, config.warmup_steps, config.num_steps, config.clip_norm)
    constants = Constants(buffers, body_model, smplx_jax.hand_model(body_model, "right"))
    state = TrainState(jnp.zeros((), jnp.int32), params, batch_stats, tx.init(params))
    return Setup(config.kind, graphdef, tx), constants, state


def network_of(setup: Setup, constants: Constants, state: TrainState) -> nnx.Module:
    """The regressor with the state's weights (inference mode)."""
    return nnx.merge(setup.graphdef, state.params, state.batch_stats, constants.buffers)


def train_step(setup: Setup, constants: Constants, state: TrainState, batch) -> tuple[TrainState, dict]:
    """One Adam step on the batch's mean loss; BatchNorm normalises with, and updates, batch statistics."""

    def loss_fn(params):
        # BatchNorm writes its statistics: their Variables must be made at this trace level (a fresh copy).
        network = nnx.merge(setup.graphdef, params, jax.tree.map(lambda a: a, state.batch_stats), constants.buffers)
        network.train()
        terms = jax.tree.map(jnp.mean, _losses(setup.kind, constants, network(batch.image), batch))
        return terms["total"], (terms, nnx.state(network, nnx.BatchStat))

    (_, (terms, batch_stats)), grads = jax.value_and_grad(loss_fn, has_aux=True)(state.params)
    updates, opt_state = setup.optimizer.update(grads, state.opt_state, state.params)
    terms["grad_norm"] = optax.global_norm(grads)
    return TrainState(state.step + 1, optax.apply_updates(state.params, updates), batch_stats, opt_state), terms


def _losses(kind, constants: Constants, output, batch) -> dict[str, jax.Array]:
    if kind == "hand":
        return jax.vmap(losses.hand_losses, in_axes=(None, None, 0, 0))(
            constants.body_model, constants.right_hand, output, batch)
    return jax.vmap(losses.body_losses, in_axes=(None, 0, 0))(constants.body_model, output, batch)


def predict_joints(kind: str, constants: Constants, output):
    """3D joints (metres) and 2D joints (crop coordinates in [-1, 1]) of a batch of network outputs."""
    if kind == "hand":
        joints = jax.vmap(losses.right_hand_joints, in_axes=(None, None, 0))(
            constants.body_model, constants.right_hand, output)
        return joints, jax.vmap(losses.hand_crop_joints)(joints, output[:, CAMERA])
    joints = jax.vmap(losses.body_joints, in_axes=(None, 0))(constants.body_model, output)
    return joints, joints[..., :2] * output.camera[:, None, :1] + output.camera[:, None, 1:]


def eval_step(setup: Setup, constants: Constants, state: TrainState, batch):
    """Predicted 3D joints (metres) and 2D joints (crop coordinates), running BatchNorm statistics."""
    return predict_joints(setup.kind, constants, network_of(setup, constants, state)(batch.image))


def example_errors(joints_3d, joints_2d, batch, root: int) -> dict[str, np.ndarray]:
    """Per example: root-aligned MPJPE and PA-MPJPE (mm), the mean 2D error in crop pixels; NaN where the example
    has no such label."""
    pred, true = metrics.root_align(joints_3d, root), metrics.root_align(batch.joints_3d, root)
    mask_3d = np.broadcast_to(np.asarray(batch.joints_3d_mask)[:, None], pred.shape[:2])
    half = batch.image.shape[1] / 2
    return dict(mpjpe_mm=1000 * metrics.mpjpe(pred, true, mask_3d),
                pa_mpjpe_mm=1000 * metrics.pa_mpjpe(pred, true, mask_3d),
                error_2d_px=metrics.mpjpe(half * joints_2d, half * batch.joints_2d, batch.joints_2d_mask))


jitted_train_step = jax.jit(train_step, static_argnums=0, donate_argnums=2)
jitted_eval_step = jax.jit(eval_step, static_argnums=0)


class Shardings(NamedTuple):
    data: NamedSharding  # the batch axis split over all devices of all hosts
    replicated: NamedSharding


def data_parallel() -> Shardings:
    mesh = Mesh(np.array(jax.devices()), ("data",))
    return Shardings(NamedSharding(mesh, PartitionSpec("data")), NamedSharding(mesh, PartitionSpec()))


def global_batch(shardings: Shardings, local_batch):
    """This host's slice of a batch -> global arrays sharded over all devices of all hosts."""
    return jax.tree.map(lambda a: jax.make_array_from_process_local_data(shardings.data, np.asarray(a)), local_batch)


def eval_batches(config: TrainConfig, dataset, count: int) -> list:
    """The first ``count`` examples (deterministic crops), in global batches; the last one padded by repetition
    (`evaluate` drops the padding)."""
    make = hand_example if config.kind == "hand" else body_example
    examples = [make(dataset[i], config.image_size) for i in range(min(count, len(dataset)))]
    examples += examples[: -len(examples) % config.batch_size]
    return [stack(examples[i:i + config.batch_size]) for i in range(0, len(examples), config.batch_size)]


def evaluate(setup: Setup, predict, state, batches_, count: int) -> dict[str, float]:
    """Means over the first ``count`` examples of the per-example errors (examples without a label left out)."""
    rows = [example_errors(*jax.device_get(predict(state, batch)), jax.device_get(batch), ROOT[setup.kind])
            for batch in batches_]
    merged = {k: np.concatenate([r[k] for r in rows])[:count] for k in rows[0]}
    return {k: float(np.nanmean(v)) if np.isfinite(v).any() else float("nan") for k, v in merged.items()}


def constant_baseline(config: TrainConfig, train_set, eval_batches_, count: int, samples: int):
    """Errors of predicting one constant pose for all: the mean root-aligned 3D joints of ``samples`` training
    examples."""
    root = ROOT[config.kind]
    train = eval_batches(config, train_set, samples)
    rel = np.concatenate([b.joints_3d - b.joints_3d[:, root:root + 1] for b in train])
    known = np.concatenate([b.joints_3d_mask for b in train])
    if not known.any():
        return {}
    mean = rel[known].mean(axis=0)
    errors = []
    for batch in eval_batches_:
        true = batch.joints_3d - batch.joints_3d[:, root:root + 1]
        error = 1000 * np.linalg.norm(true - mean, axis=-1).mean(-1)
        errors.append(np.where(batch.joints_3d_mask, error, np.nan))
    errors = np.concatenate(errors)[:count]
    return {"mpjpe_mm": float(np.nanmean(errors))} if np.isfinite(errors).any() else {}


def train_and_evaluate(config: TrainConfig, workdir: str | Path, *, model_path: str | Path | None = None) -> dict:
    """Train (resuming from ``workdir/checkpoints`` if present), evaluate every ``eval_every`` steps, write
    ``metrics.jsonl``, ``curves.png``, ``summary.json`` and the trained network to ``workdir/weights`` (the
    folder format `jaxmocap.regressors.load_network` reads). Returns the summary."""
    workdir = Path(workdir).resolve()
    workdir.mkdir(parents=True, exist_ok=True)
    body_model = smplx_jax.load_model(model_path or smplx_jax.default_model_path())
    setup, constants, state = create(config, body_model)
    shardings = data_parallel()
    if config.batch_size % jax.device_count():
        raise ValueError(f"batch_size: {config.batch_size} does not split over {jax.device_count()} devices")
    manager, state = _restored(workdir / "checkpoints", state, shardings)
    start_step = int(state.step)
    log = workdir / "metrics.jsonl"
    _truncate_log(log, start_step)

    train_set = open_dataset(config.dataset, config.data_dir, config.split)
    eval_set = open_dataset(config.eval_dataset or config.dataset, config.data_dir, config.eval_split)
    eval_count = min(config.eval_examples, len(eval_set))
    evals = [global_batch(shardings, b) for b in eval_batches(config, eval_set, eval_count)]
    evaluate_state = functools.partial(evaluate, setup, functools.partial(jitted_eval_step, setup, constants),
                                       batches_=evals, count=eval_count)
    baseline = constant_baseline(config, train_set, evals, eval_count, samples=config.eval_examples)

    stream = batches(train_set, config.batch_size, config.image_size, seed=config.seed, start_step=start_step,
                     augment=config.augment, workers=config.workers,
                     shard=(jax.process_index(), jax.process_count()))
    began = time.perf_counter()
    with log.open("a") as log_file:

        def write_row(step: int, seconds: float, row: dict) -> None:
            log_file.write(json.dumps({"step": step, "seconds": seconds} | row) + "\n")
            log_file.flush()

        state, step = _train_steps(
            config, state, start_step, began, evaluate_state=evaluate_state, write_row=write_row,
            train_step=lambda s: jitted_train_step(setup, constants, s, global_batch(shardings, next(stream))),
            save=lambda step, s: manager.save(step, args=ocp.args.StandardSave(s)))
    manager.wait_until_finished()
    final = evaluate_state(state)
    network = network_of(setup, constants, jax.device_get(state))
    if jax.process_index() == 0:
        save_weights(workdir / "weights", {config.kind: network}, {config.kind: f"train {config.dataset}"})
        plot.curves(log, workdir / "curves.png", baseline)
    summary = dict(step=step, seconds=time.perf_counter() - began, eval=final, constant_baseline=baseline,
                   examples=eval_count, devices=jax.device_count())
    (workdir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def _restored(folder: Path, state: TrainState, shardings: Shardings):
    """The checkpoint manager of ``folder`` and ``state``, restored from its latest checkpoint if any, replicated
    over the devices."""
    manager = ocp.CheckpointManager(folder, options=ocp.CheckpointManagerOptions(
        max_to_keep=2, enable_async_checkpointing=False))  # synchronous: the step donates the state buffers
    if manager.latest_step() is not None:
        state = manager.restore(manager.latest_step(), args=ocp.args.StandardRestore(state))
    return manager, jax.device_put(state, shardings.replicated)


def _train_steps(config: TrainConfig, state: TrainState, start_step: int, began: float, *, train_step,
                 evaluate_state, write_row, save) -> tuple[TrainState, int]:
    """Steps from ``start_step`` to ``config.num_steps`` (fewer once ``config.time_limit_s`` has passed since
    ``began``): losses every ``log_every`` steps, evaluation every ``eval_every``, a checkpoint every
    ``checkpoint_every``, all three at the last step. ``train_step(state)`` trains on the next batch;
    ``write_row(step, seconds, row)`` logs. Returns the state and its step."""
    step = start_step
    if step == 0:  # the untrained regressor predicts its start vector: the mean pose
        write_row(0, 0.0, {f"eval/{k}": v for k, v in evaluate_state(state).items()})
    while step < config.num_steps:
        state, terms = train_step(state)
        step += 1
        out_of_time = config.time_limit_s and time.perf_counter() - began > config.time_limit_s
        done = step == config.num_steps or out_of_time
        row = {}
        if step % config.log_every == 0 or done:
            row |= {f"train/{k}": float(v) for k, v in jax.device_get(terms).items()}
        if step % config.eval_every == 0 or done:
            row |= {f"eval/{k}": v for k, v in evaluate_state(state).items()}
        if row:
            write_row(step, time.perf_counter() - began, row)
        if step % config.checkpoint_every == 0 or done:
            save(step, state)
        if out_of_time:
            break
    return state, step


def _truncate_log(log: Path, step: int) -> None:
    """Keep only rows up to the resumed step (a killed run may have logged past its last checkpoint)."""
    if log.exists():
        rows = [line for line in log.read_text().splitlines() if line and json.loads(line)["step"] <= step]
        log.write_text("".join(line + "\n" for line in rows))
