"""Closed-form 2x2 helpers against NumPy's general routines."""

import numpy as np

from activetrack import linalg2


def test_inv2_trace_inv2_det2_match_numpy():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((200, 2, 2)) + 3 * np.eye(2)
    np.testing.assert_allclose(linalg2.inv2(A), np.linalg.inv(A), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(linalg2.det2(A), np.linalg.det(A), rtol=1e-12)
    np.testing.assert_allclose(
        linalg2.trace_inv2(A), np.trace(np.linalg.inv(A), axis1=-2, axis2=-1), rtol=1e-12
    )


def test_as_complex_views_contiguous_vectors_and_copies_others():
    rng = np.random.default_rng(1)
    v = rng.standard_normal((5, 3, 2))
    c = linalg2.as_complex(v)
    assert c.shape == (5, 3) and np.shares_memory(c, v)
    np.testing.assert_array_equal(c.real, v[..., 0])
    np.testing.assert_array_equal(c.imag, v[..., 1])
    strided = np.zeros((5, 3, 4))
    strided[..., ::2] = v
    np.testing.assert_array_equal(linalg2.as_complex(strided[..., ::2]), c)
    ints = np.array([[1, 2], [3, 4]])
    np.testing.assert_array_equal(linalg2.as_complex(ints), [1 + 2j, 3 + 4j])
