#!/usr/bin/env bash
# Spatial sensing in the demo home (docs/spatial.md): the floor plan as GeoSPARQL triples,
# sensing subscriptions named by room, simulated environment motes that honour them, and the
# per-room environment with "unknown" for what is stale. Virtual time (one hour in a second),
# so the demo is quick and the same on every run.
#
#   deploy/demo/environment.sh BIN_DIR    (BIN_DIR holds tahvel, tahvel-env-motes, tahvel-environment)
#
# Everything happens in a temporary directory that is removed at the end.
set -euo pipefail

BIN=${1:-build/bin}
for tool in tahvel tahvel-env-motes tahvel-environment; do
  if [ ! -x "$BIN/$tool" ]; then
    echo "environment.sh: no $tool in '$BIN' (build first, or pass the bin directory)" >&2
    exit 2
  fi
done
here=$(cd "$(dirname "$0")" && pwd)
plans=$here/../floorplans
work=$(mktemp -d "${TMPDIR:-/tmp}/tahvel-env-demo.XXXXXX")
trap 'rm -rf "$work"' EXIT
board="$work/home1"
home=http://example.org/home1

say() { printf '\n--- %s\n' "$*"; }
run() {
  printf '$'
  printf ' %q' "$@" | sed -e "s|$work|\$DEMO|g" -e "s|$BIN/||g" -e "s|$here/../|deploy/|g"
  printf '\n'
  "$@"
}

t0=$(( $(date +%s) * 1000000000 ))  # virtual time starts now (the subscriptions are asserted now)
at() { echo $((t0 + $1 * 1000000000)); }

say "1. The home node, its floor plan (five rooms, the living room L-shaped) and six motes."
run "$BIN/tahvel" init "$board" --iri $home
run "$BIN/tahvel" put "$board" --persistent "$plans/home.ttl" >/dev/null

say "2. Which sensors stand in the living room? (the area is a room IRI; walls count)"
run "$BIN/tahvel" list "$board" --area $home/room/living -p geo:hasGeometry

say "3. Sensing subscriptions: bedroom temperature (15 min, every 2 min above 24 C), living-room"
echo "   movement (every 60 s, every 10 s after a detection), light, kitchen temperature."
run "$BIN/tahvel" put "$board" --persistent "$plans/home-sensing.ttl" >/dev/null

say "4. One hour of virtual time: the motes sense what is asked, where and as often as asked."
run "$BIN/tahvel-env-motes" "$board" --steps 360 --step-s 10 --start-ns "$t0"

say "5. The environment per room after 50 minutes (valid time 15 minutes): the bedroom's light"
echo "   and movement were never asked for, so they are \"unknown\"."
run "$BIN/tahvel-environment" "$board" --once --valid-s 900 --now-ns "$(at 3000)"
run "$BIN/tahvel" list "$board" --area $home/room/bedroom -p tv:environment --cascade 1 --format ttl

say "6. Two hours later nothing is fresh: every value is \"unknown\"."
run "$BIN/tahvel-environment" "$board" --once --valid-s 900 --now-ns "$(at 10800)"
run "$BIN/tahvel" list "$board" -s "<$home/room/living/environment>" --format ttl

say "7. The readings of the kitchen's motes only, by area (a WKT rectangle over the kitchen)."
run "$BIN/tahvel" list "$board" --area 'POLYGON((6 0, 9 0, 9 3, 6 3, 6 0))' -p sosa:hasSimpleResult --limit 3
