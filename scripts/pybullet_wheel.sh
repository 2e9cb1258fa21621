#!/usr/bin/env bash
# Make sure the venv's Python can install pybullet 3.2.7: PyPI has wheels of it for CPython 3.6-3.11 on
# manylinux x86_64 only (upstream: bullet3 issue 4789). Where pip finds none for this interpreter, build one
# from the sdist, once, into the wheel cache outside the venv (the Makefile then installs with
# --find-links on it). Built with --no-build-isolation in the venv, which has numpy first: with build
# isolation numpy is absent and the wheel is built without numpy support (pybullet.isNumpyEnabled() == 0).
#   usage: scripts/pybullet_wheel.sh VENV_PYTHON WHEEL_CACHE
set -euo pipefail
py=$1
cache=$2
version=3.2.7
tag=$("$py" -c 'import sys; print(f"cp{sys.version_info[0]}{sys.version_info[1]}")')
mkdir -p "$cache"
if ls "$cache"/pybullet-$version-$tag-*.whl >/dev/null 2>&1; then
  echo "pybullet $version for $tag: the wheel built earlier ($(ls "$cache"/pybullet-$version-$tag-*.whl))"
  exit 0
fi
if "$py" -m pip install -q --dry-run --no-deps --only-binary=:all: "pybullet==$version" >/dev/null 2>&1; then
  exit 0  # a wheel on the index: pip installs it
fi
echo "pybullet $version has no wheel for $tag on the package index: building one from the sdist, once"
echo "(about 20-50 min on 2 cores; cached in $cache for every later venv of this Python)"
"$py" -m pip install -q numpy setuptools wheel
start=$(date +%s)
"$py" -m pip wheel -q --no-deps --no-build-isolation "pybullet==$version" -w "$cache"
echo "built $(ls "$cache"/pybullet-$version-$tag-*.whl) in $(( ($(date +%s) - start) / 60 )) min"
