"""A fitted :class:`~arxid.PolynomialModel` as JSON: its content (``to_dict``), the content of a fitted
ARX model in polynomial form (``from_arx``), and the model rebuilt from content (``from_json``)."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import numpy as np

from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError
from .derived_inputs import DerivedInput
from .files import read_text
from .filter_runs import check_initial

__all__ = ["FORMAT", "VERSION", "arx_content", "model_content", "model_from_json", "model_of"]

FORMAT = "arxid.PolynomialModel"
VERSION = 1


def model_content(model: Any) -> dict:
    """Everything needed to rebuild a fitted polynomial model.

    Parameters
    ----------
    model : PolynomialModel
        Fitted.

    Returns
    -------
    dict
    """
    model.check_fitted()
    return {
        "format": FORMAT,
        "version": VERSION,
        "orders": {
            "na": model.na_,
            "nb": list(model.nb_),
            "nc": model.nc_,
            "nd": model.nd_,
            "nf": list(model.nf_),
            "nk": list(model.nk_),
        },
        "ts": model.ts_,
        "output_name": model.output_name_,
        "input_names": list(model.input_names_),
        "output_unit": model.output_unit_,
        "input_units": list(model.input_units_),
        "parameters": [float(x) for x in model.parameters_],
        "start_parameters": [float(x) for x in model.start_parameters_],
        "covariance": [[float(x) for x in row] for row in model.covariance_],
        "n_rows": model.n_rows_,
        "n_skipped": model.n_skipped_,
        "first_lag": model.first_lag_,
        "rss": model.rss_,
        "fit_percent": model.fit_percent_,
        "iterations": model.iterations_,
        "termination": model.termination_,
        "converged": model.converged_,
        "losses": [float(x) for x in model.losses_],
        "initial": model.initial_,
        "initial_states": [[a, b, [float(x) for x in v]] for (a, b), v in model.initial_states_.items()],
        "derived_inputs": [
            {"effect": d.effect, "source": None if d.source is None else d.source.to_dict()}
            for d in model.derived_inputs
        ],
    }


def arx_content(model: Any) -> dict:
    """The content of a fitted ARX model without effect terms in polynomial form (C = D = F = 1).

    Parameters
    ----------
    model : ArxModel
        Fitted, without effect terms.

    Returns
    -------
    dict
        What :func:`model_of` reads.
    """
    model.check_fitted()
    if model.effects:
        raise ArxidError(
            f"the ARX model has effect terms {list(model.effects)}: it has no polynomial form; "
            f"use a model without effects"
        )
    m = len(model.input_names_)
    return {
        "format": FORMAT,
        "version": VERSION,
        "orders": {"na": model.na_, "nb": list(model.nb_), "nc": 0, "nd": 0, "nf": [0] * m, "nk": list(model.nk_)},
        "ts": model.ts_,
        "output_name": model.output_name_,
        "input_names": list(model.input_names_),
        "output_unit": model.output_unit_,
        "input_units": list(model.input_units_),
        "parameters": model.parameters_,
        "start_parameters": model.parameters_,
        "covariance": model.covariance_,
        "n_rows": model.n_rows_,
        "n_skipped": model.n_skipped_,
        "first_lag": model.first_lag_,
        "rss": model.rss_,
        "fit_percent": model.fit_percent_,
        "iterations": 0,
        "termination": "linear least squares (ARX)",
        "converged": True,
        "losses": [model.rss_ / model.n_rows_],
    }


def model_from_json(cls: Callable[..., Any], text_or_path: str) -> Any:
    """A model of class ``cls`` from JSON text, or from the file at that path.

    Parameters
    ----------
    cls : type
        :class:`~arxid.PolynomialModel`.
    text_or_path : str
        A JSON string or a file path.

    Returns
    -------
    PolynomialModel
    """
    text = text_or_path
    if not (isinstance(text, str) and text.lstrip().startswith("{")):
        text = read_text(text_or_path)  # a regular file of bounded size, UTF-8
    try:
        return model_of(cls, json.loads(text.removeprefix("\ufeff")))
    except RecursionError:
        raise DataError("corrupt model file: the JSON is nested too deeply") from None
    except (ValueError, KeyError, TypeError, IndexError, AttributeError, OverflowError) as exc:
        if isinstance(exc, DataError):
            raise
        raise DataError(f"corrupt model file: {exc}; write models with PolynomialModel.to_json()") from None


def model_of(cls: Callable[..., Any], d: Any) -> Any:
    """The model of ``cls`` that ``d`` describes (``ValueError``, ``KeyError`` or ``TypeError`` when it is
    not the content of a polynomial model)."""
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise ValueError("not an arxid polynomial model")
    if d.get("version") != VERSION:
        raise ValueError(f"unsupported version {d.get('version')!r}")
    o = d["orders"]
    model = cls(na=o["na"], nb=tuple(o["nb"]), nc=o["nc"], nd=o["nd"], nf=tuple(o["nf"]), nk=tuple(o["nk"]))
    fake = IOData(np.zeros(2), np.zeros((2, len(d["input_names"]))), float(d["ts"]), input_names=d["input_names"])
    model.na_, model.nb_, model.nc_, model.nd_, model.nf_, model.nk_ = model.orders_for(fake)
    model.ts_, model.output_name_ = float(d["ts"]), str(d["output_name"])
    model.input_names_ = tuple(map(str, d["input_names"]))
    model.output_unit_, model.input_units_ = str(d.get("output_unit", "")), tuple(d.get("input_units", ()))
    model.parameters_ = np.array(d["parameters"], dtype=float)
    model.start_parameters_ = np.array(d["start_parameters"], dtype=float)
    p = len(model.parameters_)
    if p != sum([model.na_, sum(model.nb_), model.nc_, model.nd_, sum(model.nf_)]):
        raise ValueError("the parameter count does not match the model structure")
    model.covariance_ = np.array(d["covariance"], dtype=float).reshape(p, p)
    model.n_rows_, model.n_skipped_, model.first_lag_ = int(d["n_rows"]), int(d["n_skipped"]), int(d["first_lag"])
    model.rss_, model.fit_percent_ = float(d["rss"]), float(d["fit_percent"])
    model.iterations_, model.termination_ = int(d["iterations"]), str(d["termination"])
    model.converged_, model.losses_ = bool(d["converged"]), np.array(d["losses"], dtype=float)
    model.initial_ = check_initial(d.get("initial", "zero"))
    model.initial_states_ = {(int(a), int(b)): np.array(v, dtype=float) for a, b, v in d.get("initial_states", [])}
    model.data_ = None
    # how the inputs the diagnosis added are computed (a term of the output: from its source's simulation)
    model.derived_inputs_ = tuple(
        DerivedInput(str(x["effect"]), None if x["source"] is None else model_of(cls, x["source"]))
        for x in d.get("derived_inputs", ())
    )
    return model
