#!/usr/bin/env bash
# Run the whole dvr_gl test suite headless. Installs the system packages the tests need
# when they are missing (Mesa EGL/llvmpipe, OSMesa, Xvfb, Chromium; apt-get, as root), then runs
# pytest and builds the documentation; fails if any test fails, if no test ran, or if the
# documentation has a warning.
set -euo pipefail
cd "$(dirname "$0")/.."

missing=()
ldconfig -p | grep -q 'libEGL.so.1 ' || missing+=(libegl1 libegl-mesa0 libgl1-mesa-dri)
ldconfig -p | grep -q 'libOSMesa.so' || missing+=(libosmesa6)
command -v Xvfb >/dev/null 2>&1 || missing+=(xvfb)
# the notebook widget is tested in JupyterLab in a real browser engine
command -v chromium >/dev/null 2>&1 || missing+=(chromium)
if [ ${#missing[@]} -gt 0 ]; then
    echo "installing system packages: ${missing[*]}"
    if [ "$(id -u)" -eq 0 ]; then SUDO=""; else SUDO="sudo"; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

# One pytest worker per core (pytest-xdist, in the dev extra), each with a one-thread
# llvmpipe: much of the suite is single-threaded NumPy (the references, the exact
# images), which then runs side by side. DVR_GL_TEST_WORKERS=1 runs it in one process,
# with llvmpipe on every core unless LP_NUM_THREADS says otherwise.
workers="${DVR_GL_TEST_WORKERS:-$(nproc)}"
parallel=()
if [ "$workers" -gt 1 ] && python -c "import xdist" 2>/dev/null; then
    parallel=(-n "$workers")
    export LP_NUM_THREADS="${LP_NUM_THREADS:-1}"
else
    export LP_NUM_THREADS="${LP_NUM_THREADS:-$(nproc)}"
fi
echo "pytest workers: ${parallel[1]:-1}, LP_NUM_THREADS=$LP_NUM_THREADS"

log=$(mktemp)
trap 'rm -f "$log"' EXIT
set +e
python -m pytest -q -p no:cacheprovider "${parallel[@]}" "$@" 2>&1 | tee "$log"
status=${PIPESTATUS[0]}
set -e
if [ "$status" -ne 0 ]; then
    exit "$status"
fi
if ! grep -Eq '[0-9]+ passed' "$log"; then   # all skipped, or nothing collected
    echo "no test ran" >&2
    exit 1
fi

# The documentation, warnings as errors: the API reference from the docstrings, the
# Markdown pages and the example gallery (examples/plot_*.py, each run headless). Built
# afresh every time (-E, the API pages and the gallery regenerated), so that neither a
# warning nor an example broken by a change elsewhere is hidden by an earlier build. The
# HTML goes to docs/_build/html (ignored by git).
echo "building the documentation"
start=$SECONDS
rm -rf docs/api/generated docs/auto_examples
python -m sphinx -E -W --keep-going -q -b html docs docs/_build/html
echo "documentation built in $((SECONDS - start)) s: docs/_build/html/index.html"
