"""The compiled growth step computes what numpy computes, bit for bit (see core/kernels.py)."""

from __future__ import annotations

import numpy as np

from growspace_sim.core import kernels


def _samples() -> np.ndarray:
    rng = np.random.default_rng(0)
    z = np.concatenate([(rng.uniform(-1, 1, 3000) + 1j * rng.uniform(-1, 1, 3000)) * scale
                        for scale in (1e-9, 1e-3, 1.0, 1e3)])
    edge = np.array([0j, 3 + 0j, -4j, 1e-300 + 1e-300j, complex(np.inf, 1), complex(1, -np.inf)])
    return np.concatenate([z, edge])


def test_complex_abs_is_numpys():
    z = _samples()
    ours = np.array([kernels._cabs(v.real, v.imag) for v in z.tolist()])
    assert np.array_equal(ours, np.abs(z))


def test_complex_over_real_is_numpys():
    z = _samples()[:-2]  # finite numerators
    d = np.random.default_rng(1).uniform(1e-6, 10.0, z.size)
    ours = np.array([kernels._divide_real(v.real, v.imag, s) for v, s in zip(z.tolist(), d)])
    assert np.array_equal(ours, z / d)


def test_bisect_is_searchsorted():
    x = np.sort(np.random.default_rng(2).integers(0, 20, 50).astype(float))
    for value in np.arange(-1.0, 21.0, 0.5):
        for right in (False, True):
            assert kernels._bisect(x, value, right) == \
                x.searchsorted(value, 'right' if right else 'left')


def test_update_photons_repoints_kills_and_keeps_order():
    """Known answer: three photons, one new node at the origin numbered 5."""
    photons = np.array([0.01 + 0j, 0.5 + 0j, 3.0 + 0j])
    x = photons.real.copy()
    column = np.array([0, 1, 2])
    node = np.array([1, 1, 1])
    distance = np.array([0.2, 0.3, 5.0])
    left = kernels.update_photons(photons, x, column, node, distance, np.array([0j]), 5, 0.05)
    assert left == 2  # the photon 0.01 m from the new node is used up
    assert photons[:2].tolist() == [0.5, 3.0] and column[:2].tolist() == [1, 2]
    assert node[:2].tolist() == [1, 5]  # 0.5 m from the new node is not nearer than 0.3
    assert distance[:2].tolist() == [0.3, 3.0]
