"""Stages run beside each other (arxid._base.background): the caller gets the value or the error."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from arxid._base.background import Background, in_two, one_blas_thread
from arxid.exceptions import DataError


def test_the_value_comes_back_and_the_stage_ran_on_another_thread():
    seen = []

    def stage(x, scale=1.0):
        seen.append(threading.current_thread() is threading.main_thread())
        time.sleep(0.05)
        return np.sum(x) * scale

    job = Background(stage, np.arange(5.0), scale=2.0)
    assert job.result() == 20.0 and seen == [False]
    assert job.result() == 20.0  # asked again: the same value


def test_the_stage_error_is_raised_to_the_caller_with_its_type_and_words():
    def stage():
        raise DataError("the validation data are too short for the test")

    job = Background(stage)
    with pytest.raises(DataError, match="too short"):
        job.result()


def test_a_diagnosis_says_what_is_wrong_with_the_validation_data_first():
    """The baseline (validation data) runs beside the scoring (estimation data); when both fail,
    the baseline's error is the one raised, as when it ran first."""
    import arxid

    rng = np.random.default_rng(0)
    u = rng.standard_normal(400)
    y = np.convolve(u, [0.0, 0.5, 0.3])[:400] + 0.01 * rng.standard_normal(400)
    model = arxid.arx(arxid.IOData(y, u, 0.01), 2, 2, 1)
    short = arxid.IOData(y[:2], u[:2], 0.01)  # too short for the prediction and for the scoring
    with pytest.raises(DataError, match="validation data .* too short for a prediction"):
        arxid.diagnose(model, short, short)


def test_in_two_keeps_the_order_and_uses_both_threads():
    threads = set()

    def square(x):
        threads.add(threading.current_thread().name)
        time.sleep(0.01)  # long enough for the second thread to take items too
        return x * x

    assert in_two(square, list(range(12))) == [x * x for x in range(12)]
    assert len(threads) == 2
    assert in_two(square, []) == [] and in_two(square, [3]) == [9]


def test_in_two_raises_the_error_of_the_first_failing_item_and_starts_none_after():
    started = []

    def check(x):
        started.append(x)
        time.sleep(0.01)
        if x in (3, 5):
            raise DataError(f"item {x} is bad")
        return x

    with pytest.raises(DataError, match="item 3"):
        in_two(check, list(range(40)))
    assert max(started) <= 6  # both threads stop at the first failure they see


def test_blas_runs_on_one_thread_inside_the_block_only():
    from threadpoolctl import threadpool_info

    def blas_threads():
        return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}

    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=2, user_api="blas"):  # as outside an analysis on two cores
        with one_blas_thread():
            assert blas_threads() == {1}
        assert blas_threads() == {2}  # restored
