#!/usr/bin/env bash
# Set up the peers' own virtual environments, outside the repository.
#
#   bash benchmarks/peers/setup.sh            # both peers (placo, then TSID)
#   bash benchmarks/peers/setup.sh placo      # only placo
#   bash benchmarks/peers/setup.sh tsid       # only TSID (builds libtsid: ~40 min on 2 cores)
#
# PEERS_DIR (default /work/peers) holds placo-venv/ and tsid-venv/.
# PYTHON (default python3.11) is the interpreter the venvs are made from.
# Only PyPI is needed.
set -euo pipefail

PEERS_DIR="${PEERS_DIR:-/work/peers}"
PYTHON="${PYTHON:-python3.11}"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
what="${1:-all}"
mkdir -p "$PEERS_DIR"

setup_placo() {
    local venv="$PEERS_DIR/placo-venv"
    [ -x "$venv/bin/python" ] || "$PYTHON" -m venv "$venv"
    "$venv/bin/pip" install --upgrade pip
    # placo's wheel pins its own Pinocchio; nothing else is shared with it.
    "$venv/bin/pip" install "placo==0.10.2" numpy
    "$venv/bin/python" -c "import placo, pinocchio; print('placo ok, pinocchio', pinocchio.__version__)"
}

setup_tsid() {
    local venv="$PEERS_DIR/tsid-venv"
    [ -x "$venv/bin/python" ] || "$PYTHON" -m venv "$venv"
    "$venv/bin/pip" install --upgrade pip
    # The tsid wheel's bindings were compiled against Pinocchio 4.0.0; libtsid
    # comes as an sdist and must be built against that same Pinocchio, so the
    # constraints hold for the install AND for the isolated build environment.
    local cons="$HERE/tsid-constraints.txt"
    export PIP_CONSTRAINT="$cons"          # install (and build env on older pip)
    export PIP_BUILD_CONSTRAINT="$cons"    # build env on pip >= 25.3
    # cmeel's build: 2 jobs (default 4) and without running libtsid's own test suite
    export CMEEL_JOBS="${CMEEL_JOBS:-2}"
    export CMEEL_RUN_TESTS="${CMEEL_RUN_TESTS:-OFF}"
    "$venv/bin/pip" install --constraint "$cons" numpy "tsid==1.10.0"
    "$venv/bin/python" -c "import pinocchio, tsid; print('tsid ok, pinocchio', pinocchio.__version__)"
}

case "$what" in
    placo) setup_placo ;;
    tsid) setup_tsid ;;
    all) setup_placo; setup_tsid ;;
    *) echo "usage: $0 [all|placo|tsid]" >&2; exit 2 ;;
esac
