"""The foundation every layer may use: the compiled Rust core (``_core``), the metrics every number
shown comes from (``metrics``), resource limits (``limits``), text formatting (``formatting``),
optional dependencies (``optional``), the package version (``version``) and nested
least-squares fits from one factorization (``nested``, the AR orders of the residual tests).

Nothing here imports another part of arxid except :mod:`arxid.exceptions`.
"""
