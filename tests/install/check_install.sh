#!/usr/bin/env bash
# Install.AnAgentBuiltOutsideTheTreeRunsAgainstTheInstalledTree SOURCE_DIR BUILD_DIR CC CXX LIBDIR
#
# What an integrator and an agent developer do with a release: `cmake --install` into a prefix,
# then build the two example agents against the installed headers and library through
# pkg-config alone (no path into the source or build tree), and run one of them against a store
# made by the installed `tahvel`: the item it derives must be on the board, written as its agent.
# Also: the installed systemd unit names the installed `tahvel`.
set -euo pipefail
src=$1 build=$2 cc=$3 cxx=$4 libdir=${5:-lib}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
prefix=$work/prefix
fail() { echo "FAIL: $*" >&2; exit 1; }

cmake --install "$build" --prefix "$prefix" > "$work/install.log" || { cat "$work/install.log" >&2; fail "cmake --install"; }
for program in tahvel tahvel-ecg-source tahvel-rpeak tahvel-rr tahvel-hrv tahvel-trend; do
  [[ -x $prefix/bin/$program ]] || fail "bin/$program is not installed"
done
grep -q "^ExecStart=$prefix/bin/tahvel up " "$prefix/lib/systemd/system/tahvel-node@.service" ||
  fail "the installed unit does not start $prefix/bin/tahvel: $(grep ExecStart "$prefix/lib/systemd/system/tahvel-node@.service")"
[[ -f $prefix/share/tahvel/home-to-hospital.toml ]] || fail "share/tahvel/home-to-hospital.toml is not installed"

# Moved after installing: the pkg-config file must find its tree where it is, not where it was.
mv "$prefix" "$work/moved"
prefix=$work/moved
export PKG_CONFIG_PATH=$prefix/$libdir/pkgconfig
flags=$(pkg-config --cflags --libs tahvel) || fail "pkg-config does not know tahvel"
[[ $flags != *"$src"* && $flags != *"$build"* ]] || fail "pkg-config points into the source or build tree: $flags"
# shellcheck source=tests/install/examples.sh
source "$src/tests/install/examples.sh"
build_and_run_examples "$prefix/bin/tahvel" "the installed tree"
echo "installed, built outside the tree, ran"
