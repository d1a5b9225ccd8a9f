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
# shellcheck disable=SC2086  # the flags are words
"$cc" -std=c99 -o "$work/example_agent" "$src/agents/examples/example_agent.c" $flags ||
  fail "the C example does not build against the build tree"
# shellcheck disable=SC2086
"$cxx" -std=c++20 -o "$work/example_agent_cpp" "$src/agents/examples/example_agent_cpp.cpp" $flags ||
  fail "the C++ example does not build against the build tree"

store=$work/home1
"$build/bin/tahvel" init "$store" --iri http://example.org/home1
"$work/example_agent" "$store" --idle 1 > /dev/null 2>&1 || fail "the C example built against the build tree failed"
"$work/example_agent_cpp" "$store" --idle 1 > /dev/null 2>&1 || fail "the C++ example built against the build tree failed"
"$build/bin/tahvel" put "$store" > /dev/null <<'TTL'
<http://example.org/home1/obs/17> <https://w3id.org/tahvel#heartRate> "112"^^<http://www.w3.org/2001/XMLSchema#integer> .
TTL
"$work/example_agent" "$store" --count 1 --idle 10 > /dev/null || fail "the C example built against the build tree failed"
"$work/example_agent_cpp" "$store" --count 1 --idle 10 > /dev/null || fail "the C++ example built against the build tree failed"
for agent in example-c example-cpp; do
  out=$("$build/bin/tahvel" list "$store" --source "http://example.org/home1/$agent" -p https://w3id.org/tahvel#heartRateClass)
  [[ $out == *'"high"'* ]] || fail "no heartRateClass \"high\" from $agent on the board: $out"
done
echo "built against the build tree through tahvel-uninstalled.pc, ran"
