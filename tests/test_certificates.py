"""The compiled Cholesky certificates and eigenvalue bounds against exact eigenvalues and the NumPy loops."""

from __future__ import annotations

import numpy as np
import pytest
from dh_arms import property_settings
from hypothesis import given
from hypothesis import strategies as st

import planner.motion.singularity as singularity
from planner import InvalidArgumentError
from planner.core.certificates import LARGEST, cholesky_certificates, extreme_bounds, grams

pytestmark = pytest.mark.skipif(
    grams(np.zeros((1, 1, 1))) is None, reason="no C compiler (or PLANNER_JIT=0): the compiled loops are off"
)


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
def test_extreme_bounds_bracket_the_extreme_eigenvalues_and_the_determinant(seed, n, k, monkeypatch_module):
    # The compiled loop and the NumPy path (its eigenvalues with a margin) alike.
    gram, values = _grams(seed, n, k)
    with monkeypatch_module.context() as patch:
        patch.setattr(singularity, "extreme_bounds", lambda gram: None)
        written_out = singularity._extreme_bounds(gram)
    for bounds in (extreme_bounds(gram), written_out):
        low_min, high_min, low_max, high_max, product = bounds.T
        assert np.all(low_min <= values[:, 0]) and np.all(high_min >= values[:, 0])
        assert np.all(low_max <= values[:, -1]) and np.all(high_max >= values[:, -1])
        assert np.all(product <= np.prod(values, axis=1) * (1 + 1e-9))
        clear = values[:, 0] > 1e-6 * values[:, -1]  # the determinant tight away from rounding
        assert np.all(product[clear] >= np.prod(values[clear], axis=1) * (1 - 1e-3))


@pytest.mark.parametrize("k", [2, 3, 6, 7])
def test_extreme_bounds_are_tight_on_most_matrices(k):
    # Not vacuous: spectra from 1e-8 to 10 (closer together than a Jacobian's, on the whole).
    gram, values = _grams(5, 1000, k)
    low_min, high_min, low_max, high_max, _ = extreme_bounds(gram).T
    assert np.mean(low_min >= values[:, 0] * (1 - 2e-4)) > 0.6
    assert np.mean(low_min >= 0.5 * values[:, 0]) > 0.95 and np.mean(high_min <= 1.01 * values[:, 0]) > 0.85
    assert np.mean(high_max <= values[:, -1] * (1 + 2e-4)) > 0.6
    assert np.mean(high_max <= 1.5 * values[:, -1]) > 0.95 and np.mean(low_max >= 0.99 * values[:, -1]) > 0.85


def test_extreme_bounds_of_degenerate_matrices():
    # Zero, singular and NaN matrices: sound bounds (NaN bounds compare false: nothing shown).
    zero = extreme_bounds(np.zeros((1, 6, 6)))[0]
    assert zero[0] == 0.0 and zero[2] <= 0.0 <= zero[3] and zero[4] == 0.0
    jac = np.random.default_rng(3).normal(size=(6, 5))
    singular = extreme_bounds((jac @ jac.T)[None])[0]
    assert singular[0] == 0.0 and 0.0 <= singular[1] < 1e-9 and singular[4] == 0.0
    nan = extreme_bounds(np.full((1, 3, 3), np.nan))[0]
    assert not nan[0] > 0.0 and not nan[4] > 0.0


@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 60), k=st.integers(1, 6), factor=st.floats(0.0, 2.0))
@property_settings(30)
def test_compiled_loops_equal_the_numpy_ones(seed, n, k, factor, monkeypatch_module):
    # The same arithmetic in the same order: the same bits.
    gram, values = _grams(seed, n, k)
    shift = values[:, 0] * factor
    compiled = cholesky_certificates(gram, shift)
    with monkeypatch_module.context() as patch:
        patch.setattr(singularity, "cholesky_certificates", lambda gram, shift: None)
        written_out = singularity._positive_definite(gram, shift)
    assert all(np.array_equal(a, b) for a, b in zip(compiled, written_out))


def test_larger_matrices_and_empty_batches():
    assert cholesky_certificates(np.eye(LARGEST + 1)[None], np.zeros(1)) is None
    assert extreme_bounds(np.eye(LARGEST + 1)[None]) is None
    assert extreme_bounds(np.zeros((0, 3, 3))).shape == (0, 5)
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
            extreme_bounds(gram)


@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 30), r=st.integers(1, 8), c=st.integers(1, 8))
@property_settings(40)
def test_grams_are_numpys_products(seed, n, r, c):
    matrices = np.random.default_rng(seed).normal(size=(n, r, c))
    want = matrices @ matrices.transpose(0, 2, 1) if r <= c else matrices.transpose(0, 2, 1) @ matrices
    got = grams(matrices)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * max(1.0, float(np.abs(matrices).max(initial=0.0))) ** 2)
    assert np.array_equal(got, got.transpose(0, 2, 1))
