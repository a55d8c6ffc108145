"""A model structure written as text, as the command line takes it: ``oe:2,2,3``, ``arx:2,2,1``.

======================  ====================================  =================================
written                 model                                  fitted by
======================  ====================================  =================================
``arx:NA,NB,NK``        A y = B u + e                          :func:`arxid.arx` (least squares)
``oe:NB,NF,NK``         y = B/F u + e                          :func:`arxid.oe`
``armax:NA,NB,NC,NK``   A y = B u + C e                        :func:`arxid.armax`
``bj:NB,NC,ND,NF,NK``   y = B/F u + C/D e                      :func:`arxid.bj`
``tf:NP,NZ``            y = N(s)/D(s) e^{-sτ} u + e            :func:`arxid.tfest` (SRIVC)
``proc:P1D``            K e^{-Td s}/(1 + Tp1 s) + e, ...       :func:`arxid.procest`
======================  ====================================  =================================

The orders follow MATLAB's argument order for each function; nb, nf and nk apply to every input.
``tf`` gives the poles and zeros of a continuous transfer function (one common denominator for
several inputs) and searches its dead time; ``proc`` takes a MATLAB process-model string
(``P1D``, ``P2DU``, ``P1DI``, ``P3Z``...).

Examples
--------
>>> from arxid.models.spec import parse_model_spec
>>> spec = parse_model_spec("oe:2,2,3")
>>> spec.kind, spec.orders, spec.name
('oe', (2, 2, 3), 'OE(2,2,3)')
"""

from __future__ import annotations

from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import OrderError
from .arx_model import ArxModel, arx
from .polynomial import PolynomialModel

# The estimators of the other structures (pem, tfest, process models) are imported by the branch
# that fits or reads them: the command line reads MODEL_FORMS for its help, a sweep fits ARX only.

__all__ = ["ModelSpec", "parse_model_spec", "MODEL_FORMS"]

#: Each structure's written form and the meaning of its numbers.
MODEL_FORMS = {
    "arx": ("arx:NA,NB,NK", ("na", "nb", "nk")),
    "oe": ("oe:NB,NF,NK", ("nb", "nf", "nk")),
    "armax": ("armax:NA,NB,NC,NK", ("na", "nb", "nc", "nk")),
    "bj": ("bj:NB,NC,ND,NF,NK", ("nb", "nc", "nd", "nf", "nk")),
    "tf": ("tf:NP,NZ", ("n_poles", "n_zeros")),
    "proc": ("proc:P1D", ("structure",)),
}


def _forms() -> str:
    return ", ".join(form for form, _ in MODEL_FORMS.values())


@record
class ModelSpec:
    """A structure to fit: the model class and its orders in MATLAB's argument order.

    Attributes
    ----------
    kind : str
        ``"arx"``, ``"oe"``, ``"armax"``, ``"bj"``, ``"tf"`` or ``"proc"``.
    orders : tuple of int
        As :data:`MODEL_FORMS` names them, e.g. (nb, nf, nk) for ``oe``; empty for ``proc``.
    process : str
        The process-model string for ``proc`` (``"P1D"``...), else ``""``.
    """

    kind: str
    orders: tuple[int, ...]
    process: str = ""

    @property
    def name(self) -> str:
        """The structure as arxid names it, e.g. ``OE(2,2,3)``, ``tf(2,1)``, ``P1D``."""
        if self.kind == "proc":
            return self.process
        if self.kind == "tf":
            return f"tf({self.orders[0]},{self.orders[1]})"
        return f"{self.kind.upper()}({','.join(map(str, self.orders))})"

    @property
    def method(self) -> str:
        """How :meth:`fit` estimates it, in words."""
        if self.kind == "arx":
            return "least squares"
        if self.kind == "tf":
            return "refined instrumental variables for continuous time (SRIVC), dead time searched"
        if self.kind == "proc":
            return "SRIVC, then a bounded prediction-error refinement"
        return "prediction-error minimisation"

    def fit(self, data: IOData) -> ArxModel | PolynomialModel:
        """The structure fitted to ``data`` (as :attr:`method` says).

        Parameters
        ----------
        data : IOData
            Estimation data.

        Returns
        -------
        ArxModel or PolynomialModel
        """
        from .pem import armax, bj, oe
        from .process_models import procest
        from .tfest import tfest

        o = self.orders
        if self.kind == "arx":
            return arx(data, o[0], o[1], o[2])
        if self.kind == "oe":
            return oe(data, o[0], o[1], o[2])
        if self.kind == "armax":
            return armax(data, o[0], o[1], o[2], o[3])
        if self.kind == "tf":
            return tfest(data, o[0], o[1], delay="estimate")
        if self.kind == "proc":
            return procest(data, self.process)
        return bj(data, o[0], o[1], o[2], o[3], o[4])


def parse_model_spec(text: str) -> ModelSpec:
    """Read ``KIND:N,N,...`` (see the table above).

    Parameters
    ----------
    text : str
        e.g. ``"oe:2,2,3"``, ``"bj:2,1,1,2,3"``, ``"armax:2,2,1,3"``, ``"arx:2,2,1"``, ``"tf:2,1"``,
        ``"proc:P1D"``.

    Returns
    -------
    ModelSpec

    Raises
    ------
    OrderError
        For an unknown structure, a wrong count of orders or an order that is not a non-negative
        integer; the message shows the correct form.
    """
    if not isinstance(text, str):
        raise OrderError(f"a model structure is written as text such as 'oe:2,2,3', got {text!r}")
    kind, sep, numbers = text.strip().partition(":")
    kind = kind.strip().lower()
    if not sep or kind not in MODEL_FORMS:
        raise OrderError(f"cannot read the model {text!r}: write one of {_forms()}, e.g. oe:2,2,3")
    form, names = MODEL_FORMS[kind]
    if kind == "proc":
        from .process_models import parse_process

        try:
            return ModelSpec(kind, (), parse_process(numbers).name)
        except OrderError as exc:
            raise OrderError(f"cannot read the model {text!r}: {exc}, e.g. proc:P1D") from None
    parts = [p.strip() for p in numbers.split(",")]
    if len(parts) != len(names) or not all(p.isdigit() for p in parts):
        raise OrderError(
            f"cannot read the model {text!r}: {kind} takes {len(names)} non-negative integers "
            f"{form.split(':')[1]} ({', '.join(names)}), e.g. {kind}:{','.join(_EXAMPLE[kind])}"
        )
    orders = tuple(int(p) for p in parts)
    if kind == "tf" and not 0 <= orders[1] < orders[0]:
        raise OrderError(
            f"cannot read the model {text!r}: tf takes NP >= 1 poles and NZ < NP zeros (a strictly proper "
            "transfer function), e.g. tf:2,1"
        )
    return ModelSpec(kind, orders)


_EXAMPLE = {
    "arx": ("2", "2", "1"),
    "oe": ("2", "2", "3"),
    "armax": ("2", "2", "1", "3"),
    "bj": ("2", "1", "1", "2", "3"),
    "tf": ("2", "1"),
}
