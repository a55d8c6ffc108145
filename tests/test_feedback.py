"""arxid.feedback: the same plant flagged under a PI controller, not flagged in open loop."""

from __future__ import annotations

import json

import numpy as np
import pytest

import arxid
from arxid.datasets import PiLoopPlant, pi_loop

SEEDS = range(6)


@pytest.mark.parametrize("seed", SEEDS)
def test_pi_loop_with_coloured_noise_is_flagged(seed):
    result = arxid.feedback(pi_loop(seed))
    assert result.feedback
    assert result.p_value < 1e-20  # the closed loop's p-values measured 1e-46 .. 1e-51
    assert result.probability > 99.9
    assert "closed loop" in result.sentence
    assert "arxid.iv" in result.consequences and "biased" in result.consequences


@pytest.mark.parametrize("seed", SEEDS)
def test_same_plant_in_open_loop_is_not_flagged(seed):
    result = arxid.feedback(pi_loop(seed, closed=False))
    assert not result.feedback
    assert result.p_value > 0.001  # the decision level; measured 0.004 .. 0.83 over seeds 0-5
    assert result.consequences == ""
    assert "open-loop" in result.sentence


def test_p_value_is_calibrated_in_open_loop():
    # without feedback the p-value is uniform: about 5 % of records below 0.05, not many more
    p = np.array([arxid.feedback(pi_loop(seed, n_samples=1500, closed=False)).p_value for seed in range(200, 240)])
    assert np.mean(p < 0.05) <= 0.15
    assert 0.3 < np.median(p) < 0.7


def test_lag_zero_controller_needs_the_default_test():
    # the PI controller reacts within the sample: with direct=True (MATLAB fbck, u(t) may act on
    # y(t)) that reaction is explained away and the evidence is much weaker than by default
    d = pi_loop(0)
    assert arxid.feedback(d, direct=True).p_value > 1e3 * arxid.feedback(d).p_value


def test_feedback_across_experiments_and_gaps():
    d = arxid.IOData.merge([pi_loop(1, 2000), pi_loop(2, 2000)])
    y = d.y.copy()
    y[500:520] = np.nan
    gappy = arxid.IOData(y, d.u, d.ts, experiment_starts=d.experiment_starts)
    result = arxid.feedback(gappy)
    assert result.feedback
    assert result.n_rows < 4000 - 2 * 21 - 20
    json.loads(result.to_json())


def test_feedback_refuses_too_short_data():
    d = pi_loop(0, 200)
    with pytest.raises(arxid.DataError, match="usable samples"):
        arxid.feedback(d, order=40, lead=40)


def test_true_plant_parameters():
    p = PiLoopPlant()
    assert p.gain == pytest.approx(0.75)
    np.testing.assert_allclose(np.abs(p.poles), np.sqrt(0.7))


def test_analyse_and_report_say_what_feedback_means():
    from arxid.analysis.report.html import render_html

    a = arxid.analyse(pi_loop(0, 2000), validation=pi_loop(1, 1000), orders=(2, 2, 1), max_steps=0)
    assert a.feedback is not None and a.feedback.feedback
    notes = " ".join(a.notes)
    assert "closed loop" in notes and "may be biased" in notes
    assert "instrumental variables" in notes
    assert a.to_dict()["feedback"]["feedback"] is True
    assert "the data were logged in closed loop" in "\n".join(a.summary_lines())
    html = render_html(a)
    assert "logged in closed loop" in html and "instrumental variables" in html
    from arxid.analysis.closed_loop import feedback_notes

    open_loop = pi_loop(0, 2000, closed=False)
    notes = feedback_notes(arxid.feedback(open_loop), open_loop)
    assert len(notes) == 1 and "open-loop" in notes[0]


@pytest.mark.parametrize("closed", [True, False])
def test_f_statistic_matches_two_least_squares_fits(closed):
    """The statistic from one blocked factor equals the textbook F-test of two numpy lstsq fits on
    the lagged matrix (gaps and two experiments included)."""
    from scipy import stats

    from arxid.models.lagged import lagged_columns

    d = arxid.IOData.merge([pi_loop(3, 70_000, closed=closed), pi_loop(4, 3000, closed=closed)])
    y = d.y.copy()
    y[900:930] = np.nan
    d = arxid.IOData(y, d.u, d.ts, experiment_starts=d.experiment_starts)
    order, lead = 4, 3
    result = arxid.feedback(d, order=order, lead=lead)
    u = d.u[:, 0]
    past = [(y, k) for k in range(1, order + 1)] + [(u, k) for k in range(1, order + 1)]
    later = [(u, -k) for k in range(0, lead + 1)]
    mat, _ = lagged_columns([(y, 0), *past, *later], d.segments, order, lead)
    rss = [
        float(np.sum((mat[:, 0] - x @ np.linalg.lstsq(x, mat[:, 0], rcond=None)[0]) ** 2))
        for x in (mat[:, 1 : 1 + len(past)], mat[:, 1:])
    ]
    q, dof = len(later), mat.shape[0] - (mat.shape[1] - 1)
    f = (rss[0] - rss[1]) / q / (rss[1] / dof)
    assert result.n_rows == mat.shape[0]
    assert result.statistic[d.input_names[0]] == pytest.approx(f, rel=1e-7)
    assert result.p_values[d.input_names[0]] == pytest.approx(stats.f.sf(f, q, dof), rel=1e-6, abs=1e-300)
