"""Arrays that grow along their first axis, kept on disk (`Columns`), written as one ``.npz`` without being held in
memory: what a recording that runs for hours needs to save its frames so far every few seconds."""

import zipfile
from pathlib import Path

import numpy as np

from smplx_jax.atomic_files import atomic_path

COPY_BYTES = 1 << 22  # the most bytes held at once while a column is copied into an .npz


class Columns:
    """Named columns in ``folder``, one raw file each (``<name>.bin``, C order), that grow by `append` and are
    written by `write_npz`; each column's dtype and shape after the row axis are fixed by the first append."""

    def __init__(self, folder):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.layout: dict[str, tuple[np.dtype, tuple[int, ...]]] = {}
        self.rows = 0

    def append(self, arrays: dict[str, np.ndarray]) -> None:
        """Rows at the end of every column: the same columns as the first append, each with the same number of
        rows, dtype and row shape."""
        arrays = {k: np.ascontiguousarray(v) for k, v in arrays.items()}
        counts = {len(v) for v in arrays.values()}
        if len(counts) != 1:
            raise ValueError(f"Columns.append: columns of different lengths {sorted(counts)}")
        layout = {k: (v.dtype, v.shape[1:]) for k, v in arrays.items()}
        if self.layout and layout != self.layout:
            raise ValueError(f"Columns.append: layout {layout} differs from the columns' {self.layout}")
        for name, array in arrays.items():
            with open(self.folder / f"{name}.bin", "ab") as fh:
                fh.write(array.tobytes())
        self.layout, self.rows = layout, self.rows + counts.pop()

    def read(self, name: str) -> np.ndarray:
        """The column ``name``, every row."""
        dtype, shape = self.layout[name]
        return np.fromfile(self.folder / f"{name}.bin", dtype, self.rows * int(np.prod(shape, dtype=np.int64))
                           ).reshape((self.rows,) + shape)


def write_npz(path, columns: list[Columns], constants: dict[str, np.ndarray]) -> Path:
    """``path`` (written atomically) holding every column of ``columns`` (as many rows each) and the arrays
    ``constants``, as ``np.savez`` would write them; the columns are copied a block at a time, never loaded whole."""
    rows = {c.rows for c in columns}
    if len(rows) > 1:
        raise ValueError(f"write_npz: columns of different lengths {sorted(rows)}")
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED, allowZip64=True) as npz:
        for table in columns:
            for name, (dtype, shape) in table.layout.items():
                with npz.open(f"{name}.npy", "w", force_zip64=True) as out:
                    header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
                              "shape": (table.rows,) + shape}
                    np.lib.format.write_array_header_1_0(out, header)
                    _copy(table.folder / f"{name}.bin", out, table.rows * int(np.prod(shape, dtype=np.int64))
                          * dtype.itemsize)
        for name, value in constants.items():
            with npz.open(f"{name}.npy", "w", force_zip64=True) as out:
                np.lib.format.write_array(out, np.asarray(value), allow_pickle=False)
    return Path(path)


def _copy(source: Path, out, size: int) -> None:
    """The first ``size`` bytes of ``source`` into ``out``, `COPY_BYTES` at a time."""
    with open(source, "rb") as fh:
        while size:
            block = fh.read(min(size, COPY_BYTES))
            if not block:
                raise OSError(f"{source}: shorter than its rows")
            out.write(block)
            size -= len(block)
