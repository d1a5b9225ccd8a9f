#!/usr/bin/env bash
# Demo.*: the job `./run.sh demo` runs (deploy/demo/home-to-hospital.sh) goes through all its
# steps, says at each what the issue asks it to show, and prints no warning or error that a
# user running it would have to wonder about (its own checks once printed a list warning for
# each wait). Usage: check-demo.sh BIN_DIR; run it inside tests/tools/netns-run.
set -uo pipefail
bin=$1
here=$(cd "$(dirname "$0")" && pwd)
out=$(mktemp)
trap 'rm -f "$out"' EXIT
"$here/../../deploy/demo/home-to-hospital.sh" "$bin" >"$out" 2>&1
status=$?
fail() {
  echo "check-demo: $*"
  echo "--- what the demo printed:"
  cat "$out"
  exit 1
}
[ "$status" -eq 0 ] || fail "the demo exited with status $status"
for step in 1 2 3 4 5 6 7; do
  grep -q "^--- $step\. " "$out" || fail "the demo did not reach step $step"
done
unexpected=$(grep -i -m 1 -e warning -e error -e "gave up" -e DIFFERENT "$out")
[ -z "$unexpected" ] || fail "the demo printed: $unexpected"
expect() { grep -qF -- "$1" "$out" || fail "the demo did not say: $1"; }
expect "at the hospital: raw signals stay home."
expect " 0 at the hospital: raw signals stay home."
expect "tv:windowSeconds at home1: 1, at home2: 0."
expect "the same range read on home2 itself is identical."
expect "Nothing of it was stored at the hospital: 0 raw records there."
expect "the hospital holds none of these readings: 0 there)"
expect "The keeper removed the display's subscription to that mote"
echo "check-demo: the demo ran all 7 steps and said what it should"
