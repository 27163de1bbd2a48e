"""Inference over shapes: the centres and intervals are the hand-derived ones, and no bound leaves its range."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddfbench.report import across_shapes as ax
from ddfbench.report.stats import holm


def test_shape_means_average_the_seeds_of_each_shape_and_drop_non_finite_values():
    pairs = [("bunny", 1.0), ("bunny", 3.0), ("cow", 5.0), ("cow", math.nan), ("cow", None)]
    assert ax.shape_means(pairs) == {"bunny": 2.0, "cow": 5.0}


def test_geometric_mean_and_its_log_t_interval():
    got = ax.geometric({"a": 1.0, "b": 100.0})
    assert got.center == pytest.approx(10.0) and got.n == 2
    # ln values 0 and ln 100: mean ln 10, std ln100 / sqrt 2, t(0.975, 1) = 12.706, half = 12.706 ln100 / 2
    half = 12.7062047 * math.log(100.0) / 2
    assert got.lo == pytest.approx(10.0 * math.exp(-half), rel=1e-6)
    assert got.hi == pytest.approx(10.0 * math.exp(half), rel=1e-6)


def test_ratio_is_the_geometric_mean_of_per_shape_ratios_over_shared_shapes():
    got = ax.ratio({"s1": 2.0, "s2": 8.0, "only_a": 1.0}, {"s1": 1.0, "s2": 2.0})
    assert got.center == pytest.approx(math.sqrt(8.0)) and got.n == 2
    # ln ratios ln 2 and ln 4: mean ln sqrt 8, std ln2 / sqrt 2, so t = mean / (std / sqrt 2) = 3 on 1 dof
    half = 12.7062047 * (math.log(2) / math.sqrt(2)) / math.sqrt(2)
    assert got.lo == pytest.approx(math.sqrt(8.0) * math.exp(-half), rel=1e-6)
    assert got.hi == pytest.approx(math.sqrt(8.0) * math.exp(half), rel=1e-6)
    assert got.p == pytest.approx(0.2048, abs=1e-4)  # 2 (1 - F_t1(3)) = 1 - 2 atan(3) / pi


def test_the_same_ratio_on_every_shape_is_certain_not_unknown():
    got = ax.ratio({"a": 2.0, "b": 4.0, "c": 6.0}, {"a": 1.0, "b": 2.0, "c": 3.0})
    assert (got.center, got.lo, got.hi, got.p) == (pytest.approx(2.0), pytest.approx(2.0), pytest.approx(2.0), 0.0)


def test_a_share_gets_the_plain_mean_and_its_t_interval_cut_to_zero_one():
    got = ax.share_mean({"a": 0.6, "b": 0.8, "c": 1.0})
    # mean 0.8, std 0.2, half width t(0.975, 2) 0.2 / sqrt 3 = 4.302653 * 0.1154701 = 0.4968275
    assert (got.center, got.n) == (pytest.approx(0.8), 3)
    assert got.lo == pytest.approx(0.8 - 0.4968275, rel=1e-6) and got.hi == 1.0
    # an F-score of exactly 1 on a shape counts as 1, not as a clipped logit that outweighs the rest
    assert ax.share_mean({"a": 1.0, "b": 0.5, "c": 0.5}).center == pytest.approx(2 / 3)


def test_holm_steps_down_and_keeps_the_order():
    assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
    # a p of 0.039, one of three comparisons, is not below 0.05 once corrected
    assert holm([0.039, 0.2, 0.5])[0] == pytest.approx(0.117)
    assert math.isnan(holm([math.nan, 0.02])[0]) and holm([math.nan, 0.02])[1] == 0.02


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.floats(0.0, 1.0), min_size=2, max_size=16))
def test_a_bounded_metric_interval_stays_inside_zero_one(values):
    got = ax.share_mean({f"s{i}": v for i, v in enumerate(values)})
    assert 0.0 <= got.lo <= got.center <= got.hi <= 1.0


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.floats(1e-9, 1e3), min_size=2, max_size=16))
def test_a_positive_metric_interval_stays_positive(values):
    got = ax.geometric({f"s{i}": v for i, v in enumerate(values)})
    assert 0.0 < got.lo <= got.center * (1 + 1e-12) and got.center <= got.hi * (1 + 1e-12)


def test_a_ratio_equal_to_the_tested_value_on_every_shape_is_not_rejected():
    """With no spread the t test is degenerate: p is 0 when the constant ratio differs from the tested one and 1 when
    it is that ratio (an equivalence bound met exactly, or ratio 1 under H0). Kills ratio_p returning 0 for both."""
    a, b = {"a": 2.0, "b": 4.0, "c": 6.0}, {"a": 1.0, "b": 2.0, "c": 3.0}
    assert ax.ratio_p(a, b) == 0.0 and ax.ratio_p(a, b, against=2.0) == 1.0
    assert ax.ratio_p(b, b) == 1.0 and ax.ratio(b, b).p == 1.0
    assert math.isnan(ax.ratio_p({"a": 2.0}, {"a": 1.0}))  # one shape: no test


def test_fmt_prints_bounds_only_where_there_are_some():
    # 10 exp(±12.706 ln 100 / 2)
    assert ax.fmt(ax.geometric({"a": 1.0, "b": 100.0})) == "10 [1.97e-12, 5.08e+13] (n 2)"
    assert ax.fmt(ax.geometric({"a": 4.0}), scale=1e3) == "4e+03 (n 1)"  # n 1: a centre, no [nan, nan]
    assert ax.fmt(ax.geometric({})) == "–"
