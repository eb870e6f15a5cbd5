#!/usr/bin/env bash
# The Python package: a fresh virtual environment (tools/.venv-python, git-ignored), the package
# installed from this clone with the one `pip install` command of the README, then its pytest
# suite (python/tests). The extension is built with the dev profile (the speed figures use
# release: tools/bench_python.sh) into the same CARGO_TARGET_DIR as the other CI steps.
#
#   tools/ci_python.sh            # build, install, test
#   PYTEST_ARGS="-k golden" tools/ci_python.sh
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$root/target}
venv=tools/.venv-python
rm -rf "$venv"
python3 -m venv "$venv"
"$venv/bin/pip" install --quiet --upgrade pip
# Test-only dependencies, pinned: the readers the tests compare against (MCAP, Parquet).
"$venv/bin/pip" install --quiet -r tools/requirements-python-test.txt
MATURIN_PEP517_ARGS="--profile ${RINGSCAN_PY_PROFILE:-dev}" \
  "$venv/bin/pip" install ./python
# From the repository root with pytest's own script: neither puts python/ on sys.path, where
# the package's sources (without the built extension) would shadow the installed package, in
# pytest and in the `python -m ringscan` children the tests start.
cd "$root"
RINGSCAN_BIN=${RINGSCAN_BIN:-} "$root/$venv/bin/pytest" -q -rs python/tests ${PYTEST_ARGS:-}
