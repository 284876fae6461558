"""Our frames against references rendered on a coarser film (reference.downsample): the box average that
maps one onto the other, and the compare stage's use of it."""

from __future__ import annotations

import numpy as np
import pytest

from render.output.compare import measure
from render.output.metrics import box_downsample, downsample_factor


def test_box_average_keeps_the_mean_radiance_of_each_coarse_pixel():
    rng = np.random.default_rng(0)
    fine = rng.random((5, 12, 18, 3)).astype(np.float32)
    coarse = box_downsample(fine, 3)
    assert coarse.shape == (5, 4, 6, 3) and coarse.dtype == np.float32
    assert coarse[2, 1, 4] == pytest.approx(fine[2, 3:6, 12:15].mean(axis=(0, 1)), rel=1e-6)
    assert coarse.mean(axis=(1, 2)) == pytest.approx(fine.mean(axis=(1, 2)), rel=1e-5)
    assert box_downsample(fine, 1) is not None and np.array_equal(box_downsample(fine, 1), fine)
    with pytest.raises(ValueError, match="must divide"):
        box_downsample(fine, 5)


@pytest.mark.parametrize(
    ("shape", "reference", "factor"),
    [
        ((4, 32, 48, 3), (4, 16, 24, 3), 2),
        ((32, 48, 3), (32, 48, 3), 1),
        ((4, 32, 48, 3), (4, 16, 16, 3), None),  # not the same factor on both axes
        ((4, 32, 48, 3), (3, 16, 24, 3), None),  # another frame count
        ((4, 30, 45, 3), (4, 20, 30, 3), None),  # 1.5 is no integer
    ],
)
def test_the_factor_is_one_integer_for_both_axes(shape, reference, factor):
    assert downsample_factor(shape, reference) == factor


def test_measure_reads_a_coarse_reference_against_the_box_average():
    rng = np.random.default_rng(1)
    fine = rng.random((6, 8, 10, 3))
    reference = box_downsample(fine, 2) * 1.02
    measured = measure(fine, reference)
    assert measured["downsample"] == 2
    assert measured["agreement"].ratio == pytest.approx((1 / 1.02,) * 3, rel=1e-9)
    same = measure(box_downsample(fine, 2), reference)
    assert measured["relmse"] == pytest.approx(same["relmse"], rel=1e-12)
    assert measured["means"] == pytest.approx(same["means"], rel=1e-12)
    assert "relmse" not in measure(fine, reference[:, :, :4])  # no integer factor: nothing to compare
