"""Shared fixtures: model files (random with official shapes, and the default model), loaded once."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

from random_model import random_model_arrays  # noqa: E402

import smplx_jax  # noqa: E402
from smplx_jax.default_model import default_model_path  # noqa: E402


@pytest.fixture(scope="session")
def random_model_dir(tmp_path_factory) -> Path:
    """A folder ``smplx.create`` reads: ``<dir>/smplx/SMPLX_NEUTRAL.npz`` with random official-shaped arrays."""
    root = tmp_path_factory.mktemp("random_model")
    (root / "smplx").mkdir()
    np.savez(root / "smplx" / "SMPLX_NEUTRAL.npz", **random_model_arrays(seed=0))
    return root


@pytest.fixture(scope="session")
def default_model_dir() -> Path:
    return default_model_path().parent.parent


@pytest.fixture(scope="session", params=["default", "random"])
def model_dir(request, default_model_dir, random_model_dir) -> Path:
    return default_model_dir if request.param == "default" else random_model_dir


_LOADED = {}


def load(model_dir: Path) -> smplx_jax.BodyModel:
    """Each model file is loaded once per session."""
    if model_dir not in _LOADED:
        _LOADED[model_dir] = smplx_jax.load_model(model_dir / "smplx" / "SMPLX_NEUTRAL.npz")
    return _LOADED[model_dir]
