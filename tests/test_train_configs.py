"""Training configs: ``smoke`` is ``synthetic`` with overrides, and ``--set`` parses each value as its field's type
or stops with one line naming the field and the type it expects."""

import dataclasses

import pytest

from train import configs
from train.main import main


def test_smoke_is_synthetic_with_overrides():
    smoke, synthetic = configs.get("smoke"), configs.get("synthetic")
    changed = {f.name for f in dataclasses.fields(smoke) if getattr(smoke, f.name) != getattr(synthetic, f.name)}
    assert changed <= {"image_size", "batch_size", "warmup_steps", "num_steps", "time_limit_s", "eval_every",
                       "eval_examples", "log_every", "checkpoint_every", "workers"}
    assert (smoke.kind, smoke.dataset, smoke.depth, smoke.start_wrist_rotvec, smoke.learning_rate) == (
        synthetic.kind, synthetic.dataset, synthetic.depth, synthetic.start_wrist_rotvec, synthetic.learning_rate)
    assert smoke.num_steps < 10 and smoke.time_limit_s == 0 and smoke.warmup_steps < smoke.num_steps


def test_set_parses_each_field_type():
    config = configs.override(configs.get("smoke"), [
        "batch_size=16", "learning_rate=3e-4", "augment=false", "dataset=rhd", "kind=body",
        "start_wrist_rotvec=0.5,0,-1", "time_limit_s=60", "workers=0", "data_dir="])
    assert (config.batch_size, config.learning_rate, config.augment, config.dataset, config.kind) == (
        16, 3e-4, False, "rhd", "body")
    assert config.start_wrist_rotvec == (0.5, 0.0, -1.0) and isinstance(config.start_wrist_rotvec[1], float)
    assert config.time_limit_s == 60.0 and config.workers == 0 and config.data_dir == ""
    for text, value in (("true", True), ("1", True), ("Yes", True), ("off", False), ("0", False)):
        assert configs.override(config, [f"augment={text}"]).augment is value


@pytest.mark.parametrize("assignment, expected", [
    ("batch_size=abc", "batch_size expects an integer"),
    ("num_steps=1.5", "num_steps expects an integer"),
    ("learning_rate=fast", "learning_rate expects a number"),
    ("augment=ture", "augment expects a boolean"),
    ("kind=face", "kind expects one of hand, body"),
    ("start_wrist_rotvec=1,2", "start_wrist_rotvec expects 3 comma-separated numbers"),
    ("start_wrist_rotvec=1,x,3", "start_wrist_rotvec expects 3 comma-separated numbers"),
])
def test_set_rejects_what_it_cannot_parse(assignment, expected):
    with pytest.raises(ValueError) as err:
        configs.override(configs.get("smoke"), [assignment])
    message = str(err.value)
    assert expected in message and f"--set {assignment}" in message and "\n" not in message


def test_set_rejects_unknown_fields():
    with pytest.raises(ValueError, match="FIELD one of kind, dataset"):
        configs.override(configs.get("smoke"), ["batch=16"])
    with pytest.raises(ValueError, match="FIELD=VALUE"):
        configs.override(configs.get("smoke"), ["batch_size"])


def test_main_stops_with_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--config", "smoke", "--workdir", str(tmp_path / "run"), "--set", "eval_every=often"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error: --set eval_every=often: eval_every expects an integer" in err
    assert not (tmp_path / "run").exists()
