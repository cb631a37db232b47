"""FrankMocap's hand and body regressors in flax nnx, their exact preprocessing, and checkpoint importers.

    regressors = jaxmocap.regressors.load("weights/")      # written by `jaxmocap convert-frankmocap`
    predictor = jaxmocap.regressors.Predictor(regressors)  # jitted, fixed batch buckets
    raw, window, valid = predict_hands(predictor, frames, frame_index, boxes, is_left)
    hands = decode_hands(model, smplx_jax.hand_model(model, "right"), raw, is_left, window)  # NaN where not valid
"""

from jaxmocap.regressors import crops
from jaxmocap.regressors.body import BodyConfig, BodyOutput, BodyRegressor
from jaxmocap.regressors.convert import convert_frankmocap
from jaxmocap.regressors.decode import (
    BodyPrediction,
    HandPrediction,
    decode_bodies,
    decode_hands,
    mirror_hand_params,
)
from jaxmocap.regressors.hand import HandConfig, HandRegressor
from jaxmocap.regressors.predict import BUCKETS, Predictor, predict_bodies, predict_hands
from jaxmocap.regressors.resnet import ResNet
from jaxmocap.regressors.weights import Regressors, WeightsError, initialised, load, load_network

__all__ = [
    "BUCKETS", "BodyConfig", "BodyOutput", "BodyPrediction", "BodyRegressor", "HandConfig", "HandPrediction",
    "HandRegressor", "Predictor", "Regressors", "ResNet", "WeightsError", "convert_frankmocap", "crops",
    "decode_bodies", "decode_hands", "initialised", "load", "load_network", "mirror_hand_params", "predict_bodies",
    "predict_hands",
]
