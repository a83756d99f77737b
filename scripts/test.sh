#!/usr/bin/env bash
# Install what the test suite needs and run it: the README's test command, and what CI runs.
# Needs Python 3.10+ with pip; installs Debian's chromium + chromium-driver (headless browser
# tests) when missing, as root or through sudo.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v chromium >/dev/null 2>&1 || ! command -v chromedriver >/dev/null 2>&1; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -q
    $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver
fi
python3 -m pip install ".[test]"
# one pytest worker per core (pytest-xdist): the suite is CPU-bound and its tests independent; one BLAS
# thread per process, so that the workers and the subprocesses they start do not oversubscribe the cores
# (482 s -> 416 s on two cores); idle workers take queued tests from busy ones (worksteal, 349 s: the README's
# command runs are one long fixture)
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}" OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}" MKL_NUM_THREADS="${MKL_NUM_THREADS:-1}"
python3 -m pytest -n auto --dist worksteal "$@"
