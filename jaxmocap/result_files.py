"""The result files (motion.npz, hands.npz): their arrays as stored, written atomically and read with a clear error;
and files' checksums (the model a result was made with)."""

import hashlib
import io
import zipfile
from pathlib import Path

import numpy as np

from jaxmocap.errors import InputError
from smplx_jax.atomic_files import atomic_write_bytes


def file_sha256(path) -> str:
    """The SHA-256 of the file at ``path`` (hex), read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def result_arrays(arrays: dict, bools: tuple[str, ...]) -> dict[str, np.ndarray]:
    """A result file's arrays as stored: float64 values as float32 (but ``fps``), the ``bools`` keys (those
    present) as bool, ``model_sha256`` (if present) as a string."""
    out = {k: np.asarray(v).astype(np.float32) if np.asarray(v).dtype == np.float64 and k != "fps" else np.asarray(v)
           for k, v in arrays.items()}
    out |= {k: np.asarray(arrays[k], bool) for k in bools if k in arrays}
    return out | ({"model_sha256": np.asarray(str(arrays["model_sha256"]))} if "model_sha256" in arrays else {})


def write_result_npz(path, arrays: dict, bools: tuple[str, ...]) -> Path:
    """A result file (motion.npz, hands.npz) written atomically, its arrays as `result_arrays` stores them."""
    buffer = io.BytesIO()
    np.savez(buffer, **result_arrays(arrays, bools))
    return atomic_write_bytes(path, buffer.getvalue())


def read_result_npz(path, what: str) -> dict[str, np.ndarray]:
    """The arrays of a result ``.npz`` (``what``: "motion", "hands"), or `InputError` naming the problem."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{what} file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
        raise InputError(f"{path} is not a readable {what} .npz ({err})") from None
