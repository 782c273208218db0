#!/bin/sh
# Prints the CPU engine's measured times and their ratios to references measured in the same
# run: the arithmetic limit (an FMA loop) and scikit-learn's lars_path on the same problem.
# scikit-learn goes into a virtual environment this script creates (target/sklearn-venv, once;
# needs PyPI). CTSID_SKLEARN_PYTHON=none skips it.
set -e
cd "$(dirname "$0")/.."
if [ -z "$CTSID_SKLEARN_PYTHON" ]; then
    venv=target/sklearn-venv
    if ! "$venv/bin/python" -c "import sklearn" 2>/dev/null; then
        python3 -m venv "$venv"
        "$venv/bin/pip" install --quiet numpy scikit-learn
    fi
    CTSID_SKLEARN_PYTHON="$PWD/$venv/bin/python"
fi
if [ "$CTSID_SKLEARN_PYTHON" = none ]; then
    unset CTSID_SKLEARN_PYTHON
else
    export CTSID_SKLEARN_PYTHON
fi
exec cargo bench --bench cpu_report
