#!/usr/bin/env bash
# The project's test command: sets up the environment when needed, checks lint and format
# (ruff), then runs every test and doctest (slow end-to-end ones included) on both cores.
# Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")"
bash setup.sh --no-run
.venv/bin/ruff check .
.venv/bin/ruff format --check .
exec .venv/bin/python -m pytest -n 2 --timeout 900 --durations 25 "$@"
