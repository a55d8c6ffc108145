"""The package version, read from the installed distribution's metadata.

The one place the number is written is Cargo.toml: maturin copies it into the wheel's metadata
(``dynamic = ["version"]`` in pyproject.toml), and this module reads it back at run time.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("arxid")
except PackageNotFoundError:  # pragma: no cover - a source tree on sys.path that was never installed
    __version__ = "0+unknown"
