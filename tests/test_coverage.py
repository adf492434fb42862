"""Input coverage of the loop's scored records (`_measured._coverage`): the shares it
reports, counted here sample by sample, and the sentences and verdicts they lead to."""

import numpy as np
import pytest

from jaxcascade._measured import _coverage
from jaxcascade._measured._scoring import RecordScore, verdict


def _rows():
    rng = np.random.default_rng(0)
    est = np.linspace(-1.0, 2.0, 301)  # the estimation range is [-1, 2]
    narrow = np.linspace(0.0, 0.6, 50)  # 0.6 of a width of 3: 20 %
    leaving = np.concatenate([np.linspace(-1.0, 2.0, 90), [2.5] * 7, [-3.0] * 3])  # 10 %
    inside = rng.uniform(-0.9, 1.9, 200)
    return _coverage.coverage(
        [("est.csv", est, 2 * est)],
        [
            ("narrow.csv", "validation", narrow, narrow),
            ("leaving.csv", "test", leaving, leaving),
            ("inside.csv", "test", inside, inside),
        ],
    )


def test_the_shares_are_the_records_own_counts():
    est, narrow, leaving, inside = _rows()
    assert (est.role, est.u_min, est.u_max, est.outside, est.span) == (
        "estimation",
        -1.0,
        2.0,
        0.0,
        1.0,
    )
    assert est.y_std == pytest.approx(np.std(2 * np.linspace(-1.0, 2.0, 301)))
    assert narrow.outside == 0.0 and narrow.span == pytest.approx(0.6 / 3)
    # 7 + 3 of 100 samples beyond [-1, 2], the farthest at -3 (2 below it, of a width of
    # 3); the overlap of [-3, 2.5] with it is all of it
    assert leaving.samples == 100 and leaving.outside == pytest.approx(0.10)
    assert leaving.beyond == pytest.approx(2 / 3) and leaving.span == 1.0
    assert est.beyond == narrow.beyond == inside.beyond == 0.0
    assert inside.outside == 0.0 and inside.span == pytest.approx((inside.u_max - inside.u_min) / 3)


def test_units_map_the_input_and_scale_the_output_spread():
    (row,) = _coverage.coverage(
        [("est.csv", np.array([-1.0, 1.0]), np.array([0.0, 2.0]))],
        [],
        u_map=lambda u: 10 * np.asarray(u) + 5,
        y_scale=3.0,
    )
    assert (row.u_min, row.u_max) == (-5.0, 15.0) and row.y_std == pytest.approx(3.0)


def test_sentences_flag_a_narrow_validation_and_a_test_that_leaves_the_range():
    rows = _rows()
    said = _coverage.sentences(rows)
    assert len(said) == 2
    assert said[0].startswith("The validation record narrow.csv spans 20 %")
    assert said[1].startswith("10.0 % of the test record leaving.csv's samples")
    assert "[-1, 2]" in said[1] and "at most 67 % of the range's width beyond it" in said[1]
    assert _coverage.uncovered(rows) == {("narrow.csv", "validation"), ("leaving.csv", "test")}
    # within the limits: nothing said
    assert _coverage.OUTSIDE == 0.01 and _coverage.SPAN == 0.5
    assert _coverage.sentences([rows[0], rows[3]]) == []


def _score(record, role, error):
    return RecordScore(
        model="m",
        record=record,
        role=role,
        error=error,
        window_error=None,
        error_from_rest=error,
        window_error_from_rest=None,
        init_samples=50,
        rmse=error,
    )


def test_the_verdict_names_the_coverage_where_the_record_is_not_covered():
    final = [_score("a.csv", "test", 0.5), _score("b.csv", "test", 0.5)]
    arx = [_score("a.csv", "test", 0.2), _score("b.csv", "test", 0.2)]
    plain, flagged = verdict(final, arx, frozenset({("b.csv", "test")}))
    assert "does not describe this system;" in plain and "coverage" not in plain
    assert "or the records do not cover the input where it was scored" in flagged
    assert verdict(final, arx) == [plain, plain.replace("a.csv", "b.csv")]
