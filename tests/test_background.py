"""Stages run beside each other (arxid._base.background): the caller gets the value or the error."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from arxid._base.background import Background
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
