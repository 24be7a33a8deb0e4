#!/bin/sh
# Install lumitrace into ./.venv (created if missing). With --docs, also the documentation
# tools (then: .venv/bin/sphinx-build -W -q docs site). With --test, also the test
# dependencies (the documentation tools among them): the Python ones, the OpenEXR C++
# headers the cube-map tests compile OpenEXR's own ImfEnvmap against (Debian/Ubuntu: libopenexr-dev, pkg-config, g++), and
# the headless Chromium the live view tests drive (chromium, chromium-driver), and
# pdftoppm (poppler-utils), which renders the datasheet's PDF in its tests, and the
# Blender environment below.
# With --blender, only the Blender environment: ./.venv-blender, Blender 4.5 LTS as a
# Python module (bpy, Python 3.11 only; it pins numpy below 2, hence a venv of its own),
# which the Blender add-on's tests and tools/blender_roundtrip.py run in (about 1 GB).
set -e
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}

# The bpy environment: Python 3.11 (BLENDER_PYTHON, else python3.11 on the PATH, else
# PYTHON where it is 3.11). Where there is none, or bpy does not install, the Blender
# tests are skipped and say why.
blender_env() {
    if [ -x .venv-blender/bin/python ] &&
            .venv-blender/bin/python -c "import bpy" >/dev/null 2>&1; then
        return 0
    fi
    py311=${BLENDER_PYTHON:-}
    if [ -z "$py311" ]; then
        for candidate in python3.11 "$PY"; do
            if command -v "$candidate" >/dev/null 2>&1 &&
                    "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
                py311=$candidate
                break
            fi
        done
    fi
    if [ -z "$py311" ]; then
        echo "note: no Python 3.11 for the Blender environment (bpy 4.5 needs it; set" \
             "BLENDER_PYTHON): the Blender tests are skipped" >&2
        return 0
    fi
    rm -rf .venv-blender
    if ! "$py311" -m venv .venv-blender ||
            ! .venv-blender/bin/python -m pip install -q 'bpy==4.5.*'; then
        rm -rf .venv-blender
        echo "note: bpy 4.5 did not install: the Blender tests are skipped" >&2
    fi
}

if [ "$1" = "--blender" ]; then
    blender_env
    exit 0
fi
# setuptools notes at every editable install of a package mapped as this one (schemas/ is
# lumitrace.schemas) that a folder named like the package could shadow it: none does here
export PYTHONWARNINGS="${PYTHONWARNINGS:+$PYTHONWARNINGS,}ignore:Editable installation"
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
if [ "$1" = "--test" ]; then
    .venv/bin/python -m pip install -q -e '.[plot,test]'
    # the EULUMDAT cross-check reader may need a Rust toolchain to build: optional
    .venv/bin/python -m pip install -q -e '.[crosscheck]' 2>/dev/null ||
        echo "note: the eulumdat cross-check reader did not install; its tests are skipped" >&2
    # system packages: OpenEXR's headers and a compiler (the ImfEnvmap oracle tests),
    # headless Chromium and its driver (the live view tests), pdftoppm (the datasheet)
    need=""
    if ! pkg-config --exists OpenEXR 2>/dev/null || ! command -v g++ >/dev/null 2>&1; then
        need="$need libopenexr-dev pkg-config g++"
    fi
    if ! command -v chromium >/dev/null 2>&1 || ! command -v chromedriver >/dev/null 2>&1; then
        need="$need chromium chromium-driver"
    fi
    if ! command -v pdftoppm >/dev/null 2>&1; then  # renders the datasheet's PDF pages
        need="$need poppler-utils"
    fi
    if [ -n "$need" ]; then
        if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
            echo "installing$need for the tests"
            apt-get update -qq >/dev/null
            # shellcheck disable=SC2086
            DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $need >/dev/null
        else
            echo "note: install$need (the tests that need them are skipped, saying why;" \
                 "LUMITRACE_SKIP_NATIVE=1 skips the OpenEXR oracle)" >&2
        fi
    fi
    blender_env
elif [ "$1" = "--docs" ]; then
    .venv/bin/python -m pip install -q -e '.[plot,docs]'
else
    .venv/bin/python -m pip install -q -e '.[plot]'
fi
# Python's bytecode of the package now: an editable install leaves it to the first run,
# and where PYTHONDONTWRITEBYTECODE is set every run would compile it again (0.15 s)
.venv/bin/python -m compileall -q service >/dev/null
# compile the photon kernels now, not in the first run: into numba's on-disk cache, and
# ahead of time into an extension module that loads without numba (needs a C compiler)
.venv/bin/python -m lumitrace.trace.aot
