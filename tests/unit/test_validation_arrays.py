"""``finite_array``: what it accepts and what it refuses, with the first bad entry named — the
same verdicts whether the quick reductions decide or the entry-by-entry check does."""

import numpy as np
import pytest

from wholebody.validation import finite_array


@pytest.mark.parametrize("value, nonnegative", [
    ([1.0, 2.0], False), ([1e308, 1e308], False),  # finite entries whose sum overflows
    ([0.0, -0.0, 3.0], True), ([], False), ([], True), ([[1.0, -2.0]], False), (7.0, True)])
def test_finite_arrays_are_accepted_as_float_arrays(value, nonnegative):
    out = finite_array(value, "x", nonnegative=nonnegative)
    assert out.dtype == float
    np.testing.assert_array_equal(out, np.asarray(value, dtype=float))


@pytest.mark.parametrize("value, nonnegative, message", [
    ([1.0, np.nan, np.inf], False, r"x: expected finite numbers, got nan at index 1"),
    ([1.0, 2.0, -np.inf], False, r"got -inf at index 2"),
    ([1e308, 1e308, np.nan], False, r"got nan at index 2"),
    ([[1.0, 2.0], [3.0, -1e-300]], True, r"expected finite numbers >= 0, got -1e-300 at index "
                                        r"\(1, 1\)"),
    ([np.inf, -1.0], True, r"got inf at index 0"),
    (-2.0, True, r"x: expected finite numbers >= 0, got -2.0$")])
def test_the_first_bad_entry_is_named(value, nonnegative, message):
    with pytest.raises(ValueError, match=message):
        finite_array(value, "x", nonnegative=nonnegative)


def test_a_shape_other_than_asked_is_refused():
    with pytest.raises(ValueError, match=r"x: expected shape \(3,\), got \(2,\)"):
        finite_array([1.0, 2.0], "x", shape=(3,))
