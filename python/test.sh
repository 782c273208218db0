#!/usr/bin/env bash
# Builds and installs the Python package into a virtual environment under target/ and runs its
# tests against the command-line binary of the same tree (built first if missing).
# Needs python3 with venv and pip, and network access for maturin, numpy, pandas and pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=target/pyenv
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/pip" install -q --upgrade pip
"$venv/bin/pip" install -q pytest pandas
"$venv/bin/pip" install -q ./python
[ -x target/release/ctsid ] || cargo build --release
CTSID_BIN="$PWD/target/release/ctsid" "$venv/bin/python" -m pytest -q python/tests "$@"
