"""Training and evaluation of jaxmocap's hand and body regressors (FrankMocap's recipe; its code was never released).

    python -m train.main --config synthetic --workdir runs/synthetic    # see train/configs for each config's result
    python -m train.evaluate --dataset freihand --data-dir DATA --weights WEIGHTS_DIR
"""
