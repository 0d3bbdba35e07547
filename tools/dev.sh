#!/usr/bin/env bash
# One entry point for a fresh Debian 12 machine: installs what orthosim needs (system packages,
# a virtual environment with pinned Python packages), then runs the demo or the test suite.
#   bash tools/dev.sh demo    install what the demo needs, then `orthosim demo` (writes out/demo/)
#   bash tools/dev.sh test    install everything (test extra, Chromium), then the whole test suite
#   bash tools/dev.sh install install everything, run nothing
set -euo pipefail
cd "$(dirname "$0")/.."
action="${1:-demo}"; shift || true

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

# System packages, installed only when missing: offscreen GL (no PyPI wheel ships it): Mesa's EGL
# (libegl-mesa0, every current Debian) and OSMesa (libosmesa6, gone from Mesa 25.1 on, so only where
# the distribution still has it); orthosim draws through whichever starts (--gl, docs/notes/install-and-gl.md).
# Chromium is only for the tests and `orthosim report --pdf`; on a stock Debian python3, the venv module.
need=()
dpkg -s libegl-mesa0 >/dev/null 2>&1 || need+=(libegl-mesa0 libegl1)
# headless Chromium prints `orthosim report --pdf` and is the browser the report tests load the page in
if [ "$action" != demo ]; then command -v chromium >/dev/null 2>&1 || need+=(chromium); fi
python3 -c 'import ensurepip, venv' >/dev/null 2>&1 || need+=(python3-venv)
osmesa_missing=0
dpkg -s libosmesa6 >/dev/null 2>&1 || osmesa_missing=1
if [ "${#need[@]}" -gt 0 ] || [ "$osmesa_missing" = 1 ]; then
    as_root apt-get update -qq  # package lists first: a fresh machine may have none
    if [ "$osmesa_missing" = 1 ] && apt-cache show libosmesa6 >/dev/null 2>&1; then need+=(libosmesa6); fi
fi
if [ "${#need[@]}" -gt 0 ]; then
    echo "dev.sh: installing system packages: ${need[*]}"
    DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq "${need[@]}" >/dev/null
fi

# Python environment: uv (only for speed; plain `pip install .` resolves the same pins) installs from
# pyproject.toml. The demo needs the package alone; the tests also need the `test` extra.
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
if [ ! -x .venv/bin/uv ]; then
    .venv/bin/python -m pip install -q --disable-pip-version-check 'uv>=0.4'
fi
# --compile-bytecode (the tests, CI): imports read ready .pyc files instead of compiling every module on
# every run where __pycache__ cannot be written (or PYTHONDONTWRITEBYTECODE is set): seconds per start.
# The demo skips it: compiling all 8,143 modules of its dependencies took 38.6 s of CPU (2026-11-28,
# load 12), where the demo imports 717; the demo writes their .pyc itself as it imports them (its
# PYTHONDONTWRITEBYTECODE dropped below: with it set and no .pyc, every later start compiled its
# imports again, 2.0 -> 4.0-4.9 s for `import orthosim.movement.simulation` on 2026-11-28).
if [ "$action" = demo ]; then extra=""; stamp=.venv/.orthosim-installed-demo; compile=""
else extra="[test]"; stamp=.venv/.orthosim-installed; compile="--compile-bytecode"; fi
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    # pyrender's fork installs the same `pyrender` folder: the old pyrender must go first, not after
    if .venv/bin/uv pip show -q --python .venv/bin/python pyrender >/dev/null 2>&1; then
        .venv/bin/uv pip uninstall -q --python .venv/bin/python pyrender
    fi
    .venv/bin/uv pip install -q $compile --python .venv/bin/python -e ".$extra"
    touch "$stamp"
fi
# the Khronos glTF validator, for the tests of animation.glb (tests/gltf_validator_helpers.py, which pins
# the same version): into .venv/npm, ignored by git; a machine without node/npm or registry skips those tests
if [ "$action" != demo ] && command -v npm >/dev/null 2>&1 && [ ! -f .venv/npm/node_modules/gltf-validator/package.json ]; then
    npm install --prefix .venv/npm --no-audit --no-fund --silent gltf-validator@2.0.0-dev.3.10 >/dev/null 2>&1 \
        || echo "dev.sh: npm could not install gltf-validator; its tests will skip"
fi
# our own sources are an editable install, which uv does not compile: without their .pyc files every
# process compiles orthosim and render again (0.19 s of CPU per process, measured); up-to-date files are skipped
.venv/bin/python -m compileall -q orthosim render bench >/dev/null

case "$action" in
    install) echo "dev.sh: installed; run .venv/bin/orthosim --help" ;;
    demo) exec env -u PYTHONDONTWRITEBYTECODE .venv/bin/orthosim demo "$@" ;;
    # pytest-xdist: one worker per core, each module on one worker (its module-wide set-ups built once)
    # the same arithmetic on every x86-64 machine for the bit-exact step guard and goldens (tests/conftest.py)
    test) export NPY_DISABLE_CPU_FEATURES="${NPY_DISABLE_CPU_FEATURES-X86_V4 AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR}"
          export OPENBLAS_CORETYPE="${OPENBLAS_CORETYPE-Haswell}"
          exec .venv/bin/python -m pytest -n auto --dist loadscope "$@" ;;
    *) echo "dev.sh: unknown action '$action' (use demo, test or install)" >&2; exit 2 ;;
esac
