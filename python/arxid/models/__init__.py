"""Models and their estimation: ARX by Householder QR (:func:`arx`, :class:`ArxModel`), polynomial
models by prediction-error minimisation (:func:`oe`, :func:`armax`, :func:`bj`, :func:`polyest`,
:class:`PolynomialModel`), the physical-effect grammar (``effects``), regressor layouts, conversion
to python-control and scipy, continuous-time conversion, and model files."""
