"""A set of 28 x 28 MNIST digit images with their labels, and the shape curriculum's order."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
import operator

import numpy as np
import numpy.typing as npt

# Digits ordered from easiest to hardest to grow, following the GrowSpace paper.
CURRICULUM_ORDER: tuple[int, ...] = (3, 6, 2, 1, 4, 5, 7, 8, 9, 0)

IMAGE_SHAPE: tuple[int, int] = (28, 28)


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
