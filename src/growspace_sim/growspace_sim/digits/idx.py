"""MNIST's IDX files: reading, finding them in a directory, downloading them, the cache dir."""

from __future__ import annotations

import gzip
import math
import os
from pathlib import Path
import shutil
import tempfile
import urllib.request
import zlib

import numpy as np

from growspace_sim.digits.digit_set import DigitSet, IMAGE_SHAPE

PathLike = str | os.PathLike[str]

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

_DOWNLOAD_TIMEOUT_S = 60.0


def read_maybe_gzip(path: Path) -> bytes:
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
    data = read_maybe_gzip(path)
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


def idx_candidates(split: str) -> tuple[list[str], list[str]]:
    if split not in _SPLIT_PREFIX:
        raise ValueError(f"split must be 'train' or 'test', got {split!r}")
    prefix = _SPLIT_PREFIX[split]

    def names(kind: str, ndim: int) -> list[str]:
        bases = [f'{prefix}-{kind}-idx{ndim}-ubyte', f'{prefix}-{kind}.idx{ndim}-ubyte']
        return [name for base in bases for name in (base, base + '.gz')]

    return names('images', 3), names('labels', 1)


def find_idx_files(directory: Path, split: str) -> tuple[Path, Path] | None:
    image_names, label_names = idx_candidates(split)
    images = next((directory / n for n in image_names if (directory / n).is_file()), None)
    labels = next((directory / n for n in label_names if (directory / n).is_file()), None)
    if images is None or labels is None:
        return None
    return images, labels


def digit_set_from_idx(images_path: Path, labels_path: Path) -> DigitSet:
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
    found = find_idx_files(directory, split)
    if found is None:
        image_names, label_names = idx_candidates(split)
        raise FileNotFoundError(
            f'no MNIST {split} IDX files in {directory}: need one of {image_names} '
            f'and one of {label_names}')
    return digit_set_from_idx(*found)


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
    image_names, label_names = idx_candidates(split)
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
