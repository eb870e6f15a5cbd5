#!/usr/bin/env bash
# Runs tools/check_mcap.py with the official MCAP readers. The script itself creates
# tools/.venv (python3 -m venv + pip install -r tools/requirements-check.txt) on first use and
# re-runs inside it; this wrapper only finds python3 and the script.
set -euo pipefail
exec python3 "$(dirname "${BASH_SOURCE[0]}")/check_mcap.py" "$@"
