#!/usr/bin/env bash
# One entry point for a fresh Debian 12 machine: installs what orthosim needs (system packages,
# a virtual environment with pinned Python packages), then runs the demo or the test suite.
#   bash tools/dev.sh demo    install, then `orthosim demo` (writes out/demo/)
#   bash tools/dev.sh test    install, then the whole test suite
#   bash tools/dev.sh install install only
set -euo pipefail
cd "$(dirname "$0")/.."
action="${1:-demo}"; shift || true

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

# System packages, installed only when missing: OSMesa (offscreen GL; no PyPI wheel ships it),
# Chromium and, on a stock Debian python3, the venv module.
need=()
dpkg -s libosmesa6 >/dev/null 2>&1 || need+=(libosmesa6)
# headless Chromium prints `orthosim report --pdf` and is the browser the report tests load the page in
command -v chromium >/dev/null 2>&1 || need+=(chromium)
python3 -c 'import ensurepip, venv' >/dev/null 2>&1 || need+=(python3-venv)
if [ "${#need[@]}" -gt 0 ]; then
    echo "dev.sh: installing system packages: ${need[*]}"
    as_root apt-get update -qq
    DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq "${need[@]}" >/dev/null
fi

# Python environment: uv installs from pyproject.toml, with tools/overrides.txt replacing
# pyrender's PyOpenGL pin (3.1.0 cannot create an OSMesa context with attributes).
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
if [ ! -x .venv/bin/uv ]; then
    .venv/bin/python -m pip install -q --disable-pip-version-check 'uv>=0.4'
fi
stamp=.venv/.orthosim-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ tools/overrides.txt -nt "$stamp" ]; then
    # --compile-bytecode: imports read ready .pyc files instead of compiling every module on every
    # run where __pycache__ cannot be written (or PYTHONDONTWRITEBYTECODE is set): seconds per start
    .venv/bin/uv pip install -q --compile-bytecode --python .venv/bin/python --override tools/overrides.txt -e '.[test]'
    touch "$stamp"
fi
# our own sources are an editable install, which uv does not compile: without their .pyc files every
# process compiles orthosim and render again (0.19 s of CPU per process, measured); up-to-date files are skipped
.venv/bin/python -m compileall -q orthosim render bench >/dev/null

export PYOPENGL_PLATFORM=osmesa
case "$action" in
    install) echo "dev.sh: installed; run .venv/bin/orthosim --help" ;;
    demo) exec .venv/bin/orthosim demo "$@" ;;
    test) exec .venv/bin/python -m pytest "$@" ;;
    *) echo "dev.sh: unknown action '$action' (use demo, test or install)" >&2; exit 2 ;;
esac
