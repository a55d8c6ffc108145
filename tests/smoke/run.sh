#!/usr/bin/env bash
# Install a built wheel into a fresh venv whose PATH has no cargo, then run the smoke suite on it.
#   tests/smoke/run.sh dist/arxid-*.whl base   # numpy, scipy and threadpoolctl only
#   tests/smoke/run.sh dist/arxid-*.whl full   # with every extra (arxid[all])
set -euo pipefail
wheel=$(realpath "$1"); kind=${2:-base}
here=$(cd "$(dirname "$0")" && pwd)
venv=$(mktemp -d "${TMPDIR:-/tmp}/arxid-smoke-$kind.XXXXXX")
trap 'rm -rf "$venv"' EXIT
python3 -m venv "$venv"
case "$kind" in
    base) spec="$wheel" ;;
    full) spec="$wheel[all]" ;;
    *) echo "usage: $0 WHEEL base|full" >&2; exit 2 ;;
esac
echo "smoke test of $(basename "$wheel") ($kind install) in a fresh venv"
# --no-compile: pip's byte-compiling of every installed module (numpy, scipy, matplotlib, pandas...) was
# most of the install's CPU time; the suite imports a few of them once.
"$venv/bin/python" -m pip install -q --no-compile --disable-pip-version-check "$spec" "pytest>=7"
# Only the venv and the system's binaries: no cargo, rustc or maturin (they live in ~/.cargo/bin and the dev venv).
cd "$venv"
env -i HOME="$HOME" PATH="$venv/bin:/usr/local/bin:/usr/bin:/bin" LANG=C.UTF-8 \
    "$venv/bin/python" -m pytest -q -c "$here/pytest.ini" --rootdir "$here" "$here"
