"""Train a regressor: ``python -m train.main --config NAME --workdir DIR [--set FIELD=VALUE ...]``.

Rerunning the same command resumes from ``DIR/checkpoints``. On several hosts, start the same command on each
with ``--distributed`` (JAX's cluster environment variables or auto-detection give the coordinator).
"""

import argparse
import json
import sys

import jax

from jaxmocap.xla_options import configure_process
from train import configs


def main(argv: list[str] | None = None) -> int:
    configure_process()  # before anything starts JAX (`jaxmocap.xla_options`)
    parser = argparse.ArgumentParser(allow_abbrev=False, prog="python -m train.main",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True, choices=configs.NAMES)
    parser.add_argument("--workdir", required=True)
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE", help="override a config field")
    parser.add_argument("--model", help="SMPL-X model file (default: the built-in body model)")
    parser.add_argument("--distributed", action="store_true", help="call jax.distributed.initialize() first")
    args = parser.parse_args(argv)
    try:
        config = configs.override(configs.get(args.config), args.set)
    except ValueError as err:
        parser.exit(2, f"{parser.prog}: error: {err}\n")
    if args.distributed:
        jax.distributed.initialize()
    from train.train import train_and_evaluate  # after initialize: it touches devices

    summary = train_and_evaluate(config, args.workdir, model_path=args.model)
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
