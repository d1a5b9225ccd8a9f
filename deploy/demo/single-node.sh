#!/usr/bin/env bash
# Tahvel on one node, through its command line: a heart-rate monitor agent subscribes to
# heart-rate observations, an ECG agent writes observations (Turtle with blank nodes), the
# monitor takes each one exactly once, and we list, remove and count what is on the board.
#
#   deploy/demo/single-node.sh build/bin/tahvel
#
# (`./run.sh demo` runs deploy/demo/home-to-hospital.sh instead: the whole hierarchy.)
#
# Everything happens in a temporary directory that is removed at the end.
set -euo pipefail

TAHVEL=${1:-build/bin/tahvel}
# The other demos take the directory of the binaries: that is taken here too.
if [ -d "$TAHVEL" ]; then TAHVEL=$TAHVEL/tahvel; fi
if [ ! -f "$TAHVEL" ] || [ ! -x "$TAHVEL" ]; then
  echo "single-node.sh: no tahvel binary at '$TAHVEL' (build first, or pass its path)" >&2
  exit 2
fi

work=$(mktemp -d "${TMPDIR:-/tmp}/tahvel-demo.XXXXXX")
trap 'rm -rf "$work"' EXIT
board="$work/home1"

say() { printf '\n--- %s\n' "$*"; }
# Shows a tahvel command as a user would type it ($DEMO: the temporary directory).
show() {
  printf '$ tahvel'
  printf ' %q' "$@" | sed "s|$work|\$DEMO|g"
  printf '\n'
}
# Shows a tahvel command, then runs it.
tahvel() {
  show "$@"
  "$TAHVEL" "$@"
}
# Shows the Turtle on standard input, puts it as agent $1 and sets $item to the item id.
put_as() {
  local agent=$1 turtle
  turtle=$(cat)
  show put "$board" --agent "$agent"
  printf '%s\n' "$turtle" | sed 's/^/    /'
  item=$(printf '%s\n' "$turtle" | "$TAHVEL" put "$board" --agent "$agent")
  echo "$item"
}

say "1. Create a whiteboard for the node http://example.org/home1 (a home gateway)."
echo "   ex: becomes a stored prefix, usable by every later command."
tahvel init "$board" --iri http://example.org/home1 --prefix ex=http://example.org/vocab#

say "2. The agent 'monitor' subscribes to heart-rate observations."
echo "   The subscription is itself written on the board; 'ecg' never learns who reads."
tahvel subscribe "$board" --agent monitor -p sosa:observedProperty -o ex:heartRate

say "3. The agent 'ecg' writes three heart-rate observations, one item each."
echo "   Each is Turtle with blank nodes: the store renames them so items never collide."
minute=0
for bpm in 72 75 71; do
  minute=$((minute + 1))
  put_as ecg <<EOF
[] a sosa:Observation ;
   sosa:observedProperty ex:heartRate ;
   sosa:madeBySensor <ecg1> ;
   sosa:hasResult [ ex:value $bpm ; ex:unit ex:beatsPerMinute ] ;
   sosa:resultTime "2026-11-21T10:0${minute}:00Z"^^xsd:dateTime .
EOF
done

say "4. The agent 'env' writes a room temperature: the monitor did not ask for it."
put_as env <<'EOF'
[] a sosa:Observation ;
   sosa:observedProperty ex:temperature ;
   sosa:madeBySensor <room1/thermometer> ;
   sosa:hasSimpleResult 21.5 .
EOF
temperature_item=$item

say "5. The monitor takes its input buffer: each observation arrives once."
while :; do
  status=0
  tahvel take "$board" --agent monitor --timeout 500 --format ttl || status=$?
  [ "$status" -eq 0 ] || break
  echo "   (taken and acknowledged)"
done
if [ "$status" -ne 3 ]; then
  echo "single-node.sh: take failed with status $status" >&2
  exit 1
fi
echo "   exit status 3: the buffer is empty, every item was delivered exactly once."

say "6. Anyone can still query the board. Results with their sub-trees (--cascade 1):"
tahvel list "$board" -p sosa:hasResult --cascade 1

say "7. The same query as JSON lines, with each record's metadata (source, times, item):"
tahvel list "$board" -p ex:value --format json

say "8. Remove the temperature item (item $temperature_item): the count of records removed."
tahvel remove "$board" --item "$temperature_item"
echo "   Observations of ex:temperature left:"
show list "$board" -o ex:temperature
left=$("$TAHVEL" list "$board" -o ex:temperature)
echo "${left:-   (none)}"

say "9. Statistics of the node."
tahvel stats "$board"

say "Done: the demo directory is removed."
