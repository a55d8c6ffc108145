#!/usr/bin/env bash
# `make wheel`: build the abi3 wheel for manylinux2014 (glibc 2.17: Ubuntu 20.04, Debian 11, RHEL 8
# and later) and the sdist into dist/, check the wheel's tag, and install it in a fresh venv without
# Rust to import it and fit a model. Every tool (maturin, ziglang, auditwheel: the `release` extra)
# lives in its own venv in the user's cache, kept between runs (see below); no other venv is touched.
#   tests/smoke/wheel.sh            # from the repository root
set -euo pipefail
cd "$(dirname "$0")/../.."
tmp=$(mktemp -d "${TMPDIR:-/tmp}/arxid-wheel.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
py=${PYTHON:-python3}
unset VIRTUAL_ENV  # make exports the dev venv's; maturin must not build for (or into) it

# The release extra, read from pyproject.toml (the one list); pip's vendored tomli before Python 3.11.
release=$("$py" -c 'exec("try:\n import tomllib\nexcept ImportError:\n from pip._vendor import tomli as tomllib")
print(" ".join(tomllib.load(open("pyproject.toml", "rb"))["project"]["optional-dependencies"]["release"]))')
# The tools' venv sits at a fixed path outside the clone: maturin --zig links through a wrapper
# script whose location cargo hashes into every crate's fingerprint, and that location follows the
# venv's path. A venv in a fresh temporary folder made cargo rebuild faer and every other crate of
# the wheel on each run (minutes on 2 cores) although target/ held them.
tools=${ARXID_RELEASE_TOOLS:-${XDG_CACHE_HOME:-$HOME/.cache}/arxid-release-tools}
echo "installing the release tools into $tools: $release"
[ -x "$tools/bin/python" ] || "$py" -m venv --clear "$tools"
"$tools/bin/python" -m pip install -q --disable-pip-version-check $release

echo "building the wheel (maturin --zig, manylinux2014, release) and the sdist -> dist/"
rm -rf dist
{ PATH="$tools/bin:$PATH" "$tools/bin/maturin" build --release --zig --compatibility manylinux2014 --out dist \
    && "$tools/bin/maturin" sdist --out dist; } > "$tmp/build.log" 2>&1 || { cat "$tmp/build.log"; exit 1; }
wheel=$(ls dist/*.whl)
"$tools/bin/python" -m auditwheel show "$wheel"
case "$(basename "$wheel")" in
    *-abi3-*manylinux2014_x86_64*.whl | *-abi3-*manylinux_2_17_x86_64*.whl) echo "tag ok: $(basename "$wheel")" ;;
    *) echo "wrong tag: $(basename "$wheel") is not an abi3 manylinux2014 (manylinux_2_17) wheel" >&2; exit 1 ;;
esac

# `make smoke` skips this check (ARXID_WHEEL_CHECK=0): its base run (tests/smoke/run.sh) installs the
# wheel the same way and checks the same and more.
if [ "${ARXID_WHEEL_CHECK:-1}" = 0 ]; then ls -1 dist; exit 0; fi
echo "installing it in a fresh venv without cargo on PATH, then importing it and fitting a model"
"$py" -m venv "$tmp/smoke"
"$tmp/smoke/bin/python" -m pip install -q --no-compile --disable-pip-version-check "$wheel"
cd "$tmp"
env -i HOME="$HOME" PATH="$tmp/smoke/bin:/usr/bin:/bin" LANG=C.UTF-8 "$tmp/smoke/bin/python" -c '
import shutil, numpy as np, arxid
assert shutil.which("cargo") is None and shutil.which("rustc") is None, "Rust is on PATH"
rng = np.random.default_rng(0)
u = rng.standard_normal(500)
y = np.convolve(u, [0.0, 0.5, 0.25])[:500]
m = arxid.arx(arxid.IOData(y, u, ts=0.01), 1, 2, 1)
assert np.allclose(m.parameters_, [0.0, 0.5, 0.25], atol=1e-9), m.parameters_
print("smoke ok: arxid", arxid.__version__, "from", arxid.__file__)
'
ls -1 "$OLDPWD/dist"
