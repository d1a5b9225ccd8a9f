#!/usr/bin/env bash
# Install.AnAgentBuiltAgainstTheBuildTreeRunsThroughTahvelUninstalledPc SOURCE_DIR BUILD_DIR CC CXX
#
# A developer who has built the tree and writes an agent of their own, without installing:
# PKG_CONFIG_PATH=BUILD_DIR, and pkg-config's `tahvel` is the build tree's (tahvel-uninstalled.pc).
# Both examples built so must run against a store made by the build's `tahvel`.
set -euo pipefail
src=$1 build=$2 cc=$3 cxx=$4
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

export PKG_CONFIG_PATH=$build
unset PKG_CONFIG_DISABLE_UNINSTALLED
flags=$(pkg-config --cflags --libs tahvel) || fail "pkg-config does not find tahvel-uninstalled.pc in $build"
[[ $flags == *"-I$src/node/include"* && $flags == *"-L$build/lib"* ]] || fail "pkg-config does not point into this tree: $flags"
# shellcheck source=tests/install/examples.sh
source "$src/tests/install/examples.sh"
build_and_run_examples "$build/bin/tahvel" "the build tree"
echo "built against the build tree through tahvel-uninstalled.pc, ran"
