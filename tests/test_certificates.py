"""The compiled Cholesky certificates and Rayleigh bounds against exact eigenvalues and the NumPy loops."""

from __future__ import annotations

import numpy as np
import pytest
from dh_arms import property_settings
from hypothesis import given
from hypothesis import strategies as st

import planner.motion.singularity as singularity
from planner import InvalidArgumentError
from planner.core.certificates import LARGEST, cholesky_certificates, rayleigh_bounds


def _grams(seed: int, n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Gram matrices with known spectra (eigenvalues from 1e-8 to 10, ascending)."""
    rng = np.random.default_rng(seed)
    basis = np.linalg.qr(rng.normal(size=(n, k, k)))[0]
    values = np.sort(10.0 ** rng.uniform(-8, 1, (n, k)), axis=1)
    return basis @ (values[:, :, None] * basis.transpose(0, 2, 1)), values


@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 60), k=st.integers(1, 6), factor=st.floats(0.0, 2.0))
@property_settings(60)
def test_certificate_holds_exactly_where_the_eigenvalues_allow(seed, n, k, factor):
    gram, values = _grams(seed, n, k)
    shift = values[:, 0] * factor
    ok, product = cholesky_certificates(gram, shift)
    trace = values.sum(axis=1)
    # Shown positive definite only where it is; shown wherever it clearly is.
    assert not np.any(ok & (values[:, 0] <= shift))
    assert ok[values[:, 0] - shift > 1e-10 * trace].all()
    excess = np.prod(values - shift[:, None], axis=1)
    assert np.all(product[ok] <= excess[ok] * (1 + 1e-6)) and np.all(product[~ok] == 0.0)


@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 60), k=st.integers(1, 6))
@property_settings(60)
def test_rayleigh_bounds_bracket_the_extreme_eigenvalues(seed, n, k):
    gram, values = _grams(seed, n, k)
    ok = cholesky_certificates(gram, np.zeros(n))[0]
    smallest, largest = rayleigh_bounds(gram[ok])
    assert np.all(smallest >= values[ok, 0]) and np.all(largest <= values[ok, -1])


@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 60), k=st.integers(1, 6), factor=st.floats(0.0, 2.0))
@property_settings(30)
def test_compiled_loops_equal_the_numpy_ones(seed, n, k, factor, monkeypatch_module):
    # The same arithmetic in the same order: the same bits.
    gram, values = _grams(seed, n, k)
    shift = values[:, 0] * factor
    compiled = cholesky_certificates(gram, shift), rayleigh_bounds(gram[values[:, 0] > 1e-6])
    with monkeypatch_module.context() as patch:
        patch.setattr(singularity, "cholesky_certificates", lambda gram, shift: None)
        patch.setattr(singularity, "rayleigh_bounds", lambda gram: None)
        written_out = (
            singularity._positive_definite(gram, shift),
            singularity._rayleigh_bounds(gram[values[:, 0] > 1e-6]),
        )
    for got, want in zip(compiled, written_out):
        assert all(np.array_equal(a, b) for a, b in zip(got, want))


def test_larger_matrices_and_empty_batches():
    assert cholesky_certificates(np.eye(LARGEST + 1)[None], np.zeros(1)) is None
    assert rayleigh_bounds(np.eye(LARGEST + 1)[None]) is None
    ok, product = cholesky_certificates(np.zeros((0, 3, 3)), np.zeros(0))
    assert ok.shape == product.shape == (0,)


@pytest.fixture(scope="module")
def monkeypatch_module():
    with pytest.MonkeyPatch.context() as patch:
        yield patch


def test_batches_of_the_wrong_shape_are_refused_not_read_past_their_end():
    # The C loops read N k^2 matrix entries and N shifts: a short shift or a non-square matrix
    # was read past its end.
    eyes = np.eye(3)[None].repeat(4, axis=0)
    with pytest.raises(InvalidArgumentError, match=r"shift must have shape \(4,\)"):
        cholesky_certificates(eyes, np.zeros(1))
    for gram in (np.zeros((4, 3, 2)), np.zeros((3, 3))):
        with pytest.raises(InvalidArgumentError, match=r"gram must have shape \(N, k, k\)"):
            cholesky_certificates(gram, np.zeros(len(gram)))
        with pytest.raises(InvalidArgumentError, match=r"gram must have shape \(N, k, k\)"):
            rayleigh_bounds(gram)
