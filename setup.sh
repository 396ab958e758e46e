#!/usr/bin/env bash
# One command for a new machine: system library, virtual environment, the project and its
# extras, then the main job on the bundled samples.
#   bash setup.sh              set up and run the main job
#   bash setup.sh --no-run     set up only (used by test.sh)
set -euo pipefail
cd "$(dirname "$0")"

run_main_job=1
[[ "${1:-}" == "--no-run" ]] && run_main_job=0

# Open3D's wheel links libusb-1.0 at import time.
if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
    echo "installing libusb-1.0-0 (needed by Open3D)"
    SUDO=""; [[ $(id -u) -ne 0 ]] && SUDO="sudo"
    $SUDO apt-get install -y libusb-1.0-0 >/dev/null 2>&1 \
        || { $SUDO apt-get update >/dev/null && $SUDO apt-get install -y libusb-1.0-0 >/dev/null; }
fi

PYTHON="${PYTHON:-python3.11}"
command -v "$PYTHON" >/dev/null || PYTHON=python3
if [[ ! -x .venv/bin/python ]]; then
    "$PYTHON" -m venv .venv
fi
stamp=.venv/.rsodb-installed
if [[ ! -f $stamp || pyproject.toml -nt $stamp ]]; then
    .venv/bin/python -m pip install --quiet --upgrade pip
    # The 'cycles' extra (Blender's bpy) exists for CPython 3.11 only.
    extras="dev"
    .venv/bin/python -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' && extras="dev,cycles"
    .venv/bin/python -m pip install --quiet -e ".[$extras]"
    touch "$stamp"
fi
# Byte-code for the project's own modules, as pip writes it for installed packages: an editable
# install leaves that to the first import, and where Python may not write it (a read-only tree,
# PYTHONDONTWRITEBYTECODE) every command would compile the project again (~0.1 s of start-up).
.venv/bin/python -m compileall -q -j 0 ingest raycast rsodb >/dev/null

if [[ $run_main_job -eq 1 ]]; then
    # The main job: ingest the samples, find every pass's period, a short spin-state fit of every
    # pass, HTML reports; it ends by printing the path of reports/index.html.
    rm -rf archive reports
    .venv/bin/rsodb pipeline data_samples --archive archive --out reports
fi
