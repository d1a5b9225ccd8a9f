#!/usr/bin/env bash
# The home-to-hospital hierarchy of deploy/home-to-hospital.toml on this machine, in a private
# network namespace (loopback only): ECG on the sensor nodes -> HRV at each home -> HRV at the
# hospital; a window change from the hospital for one home; a query from the hospital for a time
# range of home 2's raw ECG, which never left the home (as records, then as numbers); a query by area for one room's
# environment readings; an area subscription that follows a moved mote. Says what happens at
# each step.
#
#   deploy/demo/home-to-hospital.sh [build/bin]        (what `./run.sh demo` runs)
#
# The sensors replay a synthetic ECG, or MIT-BIH records 100 and 119 when TAHVEL_MITDB is set.
# Everything lives in a temporary directory that is removed at the end.
set -euo pipefail

BIN=$(cd "${1:-build/bin}" && pwd)
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
if [ "${TAHVEL_IN_NETNS:-}" != 1 ]; then
  exec "$root/tests/tools/netns-run" "$0" "$BIN"
fi
for tool in tahvel tahvel-ecg-source tahvel-rpeak tahvel-rr tahvel-hrv tahvel-trend tahvel-env-motes tahvel-environment; do
  [ -x "$BIN/$tool" ] || { echo "home-to-hospital.sh: no $tool in $BIN (build first)" >&2; exit 2; }
done

work=$(mktemp -d "${TMPDIR:-/tmp}/tahvel-hierarchy.XXXXXX")
state=$work/state
cleanup() {
  "$BIN/tahvel" down --state "$state" >/dev/null 2>&1 || true
  [ -n "${TAHVEL_DEMO_KEEP:-}" ] || rm -rf "$work"
}
trap cleanup EXIT

H=http://example.org/hospital
say() { printf '\n--- %s\n' "$*"; }
show() { printf '$ tahvel'; printf ' %q' "$@" | sed -e "s|$work|\$DEMO|g"; printf '\n'; }
tahvel() { show "$@"; "$BIN/tahvel" "$@"; }
# The demo's own checks. Many of them expect nothing at first (no HRV window yet, no raw ECG at
# the hospital): list's warning that the store holds no record with the predicate asked for,
# meant for a user who mistyped one, is left out of what they show; any other message is not.
quiet() {
  local err status=0
  err=$(mktemp "$work/stderr.XXXXXX")
  "$BIN/tahvel" "$@" 2>"$err" || status=$?
  grep -v "has no record with the predicate" "$err" >&2 || true
  rm -f "$err"
  return "$status"
}
count() { quiet list "$@" | wc -l; }
# Waits up to $1 seconds for the command after it to succeed.
wait_for() {
  local limit=$1; shift
  for _ in $(seq $((limit * 5))); do "$@" && return 0; sleep 0.2; done
  echo "home-to-hospital.sh: gave up waiting for: $*" >&2
  return 1
}
hrv_from() { quiet list "$state/hospital" -p sosa:observedProperty -o tv:HeartRateVariability --format json |
  grep -c "\"source\":\"$H/$1/hrv\"" || true; }
has_hrv_from() { [ "$(hrv_from "$1")" -ge "$2" ]; }

say "1. Bring up the hierarchy: a hospital, two homes over Cyclone DDS, an ECG sensor node per home over LCM."
echo "   Each node gets a store under \$DEMO/state/<node>, a link process and its agents, under one supervisor."
tahvel up "$here/../home-to-hospital.toml" --state "$state"

say "2. Wait for HRV windows (60 s of ECG each; the sensors replay at 10x) to reach the hospital from both homes."
wait_for 120 has_hrv_from home1 2
wait_for 120 has_hrv_from home2 2
tahvel status --state "$state"
echo
echo "   HRV windows at the hospital: $(hrv_from home1) from home1, $(hrv_from home2) from home2 (source = each home's HRV agent)."
quiet list "$state/hospital" -p tv:rmssdMs | head -n 2
echo "   Raw ECG chunks: $(count "$state/home1" -p a -o tv:EcgChunk) at home1, $(count "$state/home2" -p a -o tv:EcgChunk) at home2," \
     "$(count "$state/hospital" -p a -o tv:EcgChunk) at the hospital: raw signals stay home."
echo "   The operator's view at the hospital: each patient's latest HRV window and trends (tahvel-trend runs there):"
tahvel patients "$state/hospital"

say "3. From the hospital, change home1's HRV window to 30 s: a configuration item addressed to <$H/home1/hrv>."
ttl=$work/window.ttl
echo "<$H/home1/hrv> <https://w3id.org/tahvel#windowSeconds> 30 ." >"$ttl"
tahvel put "$state/hospital" --agent operator --context "$H/home1/hrv" --format ttl "$ttl"
thirty_from_home1() {
  quiet list "$state/hospital" -p tv:windowStartS --format json | grep "$H/home1/" | sed 's/.*"value":"\([0-9.]*\)".*/\1/' >"$work/starts"
  # A 30 s window starts at a multiple of 30 that is not a multiple of 60.
  awk '{ if ($1 % 60 == 30) n++ } END { exit !(n >= 1) }' "$work/starts"
}
wait_for 120 thirty_from_home1
echo "   home1 now sends 30 s windows; the configuration is on home1's board only:"
echo "   tv:windowSeconds at home1: $(count "$state/home1" -p tv:windowSeconds), at home2: $(count "$state/home2" -p tv:windowSeconds)."

say "4. From the hospital, ask home2 for 10 s of its raw ECG, from 20.5 s into its recording (by the samples' time):
   the query travels down and back with the 11 one-second chunks that cover those 10 s."
first=$(quiet list "$state/home2" -p tv:samples --limit 1 --format json | sed 's/.*"asserted_at":\([0-9]*\).*/\1/')
since=$((first + 20500000000))
until=$((first + 30500000000))
show query "$state/hospital" --at "$H/home2" -p tv:samples --since "$since" --until "$until"
quiet query "$state/hospital" --at "$H/home2" -p tv:samples --since "$since" --until "$until" >"$work/remote.nt"
# The same range read on home2's own store (a query at the node itself is answered locally).
quiet query "$state/home2" --at "$H/home2" -p tv:samples --since "$since" --until "$until" >"$work/local.nt" 2>/dev/null
echo "   $(wc -l <"$work/remote.nt") chunk records, $(wc -c <"$work/remote.nt") bytes from the hospital's query;" \
     "the same range read on home2 itself is $(cmp -s "$work/remote.nt" "$work/local.nt" && echo identical || echo DIFFERENT)."
if ! cmp -s "$work/remote.nt" "$work/local.nt"; then
  echo "home-to-hospital.sh: the hospital's answer differs from what home2 holds:" >&2
  diff "$work/remote.nt" "$work/local.nt" | head -n 5 >&2 || true
  exit 1
fi
echo "   Nothing of it was stored at the hospital: $(count "$state/hospital" -p tv:samples) raw records there."
echo "   The same 10 s as numbers, one row per frame, each lead in mV (the recording's own description says how):"
rec=$(quiet list "$state/home2" -p a -o tv:EcgRecording --limit 1 | sed 's/^<\([^>]*\)>.*/\1/')
show ecg "$state/hospital" --at "$H/home2" --recording "$rec" --since "$since" --until "$until"
quiet ecg "$state/hospital" --at "$H/home2" --recording "$rec" --since "$since" --until "$until" >"$work/ecg.csv"
echo "   $(($(wc -l <"$work/ecg.csv") - 1)) frames; the first three:"
head -n 4 "$work/ecg.csv" | sed 's/^/   /'

say "5. From the hospital, ask home1 what its motes sensed in the bedroom: a query by area, resolved on home1's floor plan."
has_bedroom_readings() { [ "$(quiet list "$state/home1" --area "$H/home1/room/bedroom" | wc -l)" -gt 0 ]; }
wait_for 60 has_bedroom_readings
show query "$state/hospital" --at "$H/home1" --area "$H/home1/room/bedroom" --format ttl
quiet query "$state/hospital" --at "$H/home1" --area "$H/home1/room/bedroom" --format ttl 2>/dev/null >"$work/bedroom.ttl"
echo "   ... $(grep -c 'hasSimpleResult' "$work/bedroom.ttl") readings; the last one:"
grep -v '^@prefix' "$work/bedroom.ttl" | grep -v '^$' | tail -n 6
echo "   (the motes of the other rooms are not in the answer; the hospital holds none of these readings:" \
     "$(count "$state/hospital" -p sosa:hasSimpleResult) there)"

say "6. At home1, a carer's display subscribes to the living room's readings: an area subscription, kept current by home1's area keeper."
tahvel subscribe "$state/home1" --agent carer-display --area "$H/home1/room/living" -p sosa:hasSimpleResult
echo "   The next reading from a living-room mote (movement is sensed every 10-60 s):"
tahvel take "$state/home1" --agent carer-display --timeout 90000 --format ttl | grep -v '^@prefix' | grep -v '^$'
follows() { [ "$(quiet list "$state/home1" -p tv:source -o "$H/home1/mote-living-1" | wc -l)" -eq "$1" ]; }
echo "   Carry mote-living-1 into the kitchen (a new position is a new geo:asWKT record):"
echo "<$H/home1/mote-living-1/geometry> <http://www.opengis.net/ont/geosparql#asWKT> \"POINT(7 1)\"^^<http://www.opengis.net/ont/geosparql#wktLiteral> ." >"$work/move.nt"
tahvel put "$state/home1" --agent carer --persistent --format nt "$work/move.nt"
wait_for 10 follows 0
echo "   The keeper removed the display's subscription to that mote: its readings no longer reach the display."

say "7. Bring it down (the stores stay until this demo removes its directory)."
tahvel down --state "$state"
