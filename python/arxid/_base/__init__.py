"""The foundation every layer may use: the compiled Rust core (``_core``), the metrics every number
shown comes from (``metrics``), resource limits (``limits``), text formatting (``formatting``),
optional dependencies (``optional``) and the package version (``version``).

Nothing here imports another part of arxid except :mod:`arxid.exceptions`.
"""
