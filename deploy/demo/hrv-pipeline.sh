#!/usr/bin/env bash
# The HRV pipeline on one node, as whiteboard agents (docs/agents.md): an ECG source replays a
# MIT-BIH record, tahvel-rpeak finds the R peaks, tahvel-rr the RR intervals and which are
# normal-to-normal, tahvel-hrv the HRV per 5-minute window. The agents never talk to each
# other: each reads what it subscribed to from the whiteboard and writes what it derives.
#
#   deploy/demo/hrv-pipeline.sh BIN_DIR        (BIN_DIR holds tahvel and the tahvel-* agents)
#
# The record: $TAHVEL_MITDB/100 (default ../shared/data/mitdb beside the source tree); without
# it a synthetic ECG (ECGSYN) of 15 minutes is used. Everything happens in a temporary
# directory that is removed at the end.
set -euo pipefail

BIN=${1:-build/bin}
for tool in tahvel tahvel-ecg-source tahvel-rpeak tahvel-rr tahvel-hrv; do
  if [ ! -x "$BIN/$tool" ]; then
    echo "hrv-pipeline.sh: no $tool in '$BIN' (build first, or pass the bin directory)" >&2
    exit 2
  fi
done
here=$(cd "$(dirname "$0")" && pwd)
mitdb=${TAHVEL_MITDB:-$here/../../../shared/data/mitdb}
record=$mitdb/100

work=$(mktemp -d "${TMPDIR:-/tmp}/tahvel-hrv-demo.XXXXXX")
pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
board="$work/home1"

say() { printf '\n--- %s\n' "$*"; }
show() {
  printf '$'
  printf ' %q' "$@" | sed -e "s|$work|\$DEMO|g" -e "s|$BIN/||g"
  printf '\n'
}
run() {
  show "$@"
  "$@"
}
tahvel() { run "$BIN/tahvel" "$@"; }
# Starts an agent in the background, its messages in $work/<name>.log.
start() {
  local name=$1
  shift
  show "$BIN/$name" "$@" '&'
  "$BIN/$name" "$@" >"$work/$name.log" 2>&1 &
  pids+=($!)
}

say "1. Create the whiteboard of the home node http://example.org/home1."
tahvel init "$board" --iri http://example.org/home1

say "2. Start the three processing agents. Each subscribes to what it needs, on the board:"
echo "   tahvel-rpeak to ECG chunks, tahvel-rr to R-peak items, tahvel-hrv to RR items."
start tahvel-rpeak "$board"
start tahvel-rr "$board"
start tahvel-hrv "$board"

if [ -f "$record.hea" ]; then
  say "3. Replay MIT-BIH record 100 (30 minutes) at 200x real time: one chunk item per second."
  source_args=(--record "$record" --speed 200)
  windows=$("$BIN/tahvel" hrv "$record" --json | grep -o '"start_s"' | wc -l)
else
  say "3. No MIT-BIH record at $record: a synthetic ECG of 15 minutes at 100x real time instead."
  source_args=(--synthetic --seed 7 --seconds 900 --speed 100)
  windows=3
fi
show "$BIN/tahvel-ecg-source" "$board" "${source_args[@]}"
"$BIN/tahvel-ecg-source" "$board" "${source_args[@]}"
# The source names the recording by its record and start: .../recording/100-20261130T174900Z.
recording=$("$BIN/tahvel" list "$board" -p rdf:type -o tv:EcgRecording | sed -n 's/^<\([^>]*\)>.*/\1/p' | head -n 1)
echo "   The recording: <$recording>"

say "4. Wait until the $windows HRV windows are on the board (each new record wakes the wait)."
deadline=$((SECONDS + 300))
while :; do
  have=$("$BIN/tahvel" list "$board" -p tv:windowStartS | wc -l)
  echo "   $have of $windows windows"
  [ "$have" -ge "$windows" ] && break
  if [ "$SECONDS" -ge "$deadline" ]; then
    echo "hrv-pipeline.sh: the windows did not all arrive; agent logs:" >&2
    cat "$work"/*.log >&2
    exit 1
  fi
  timeout 10 "$BIN/tahvel" tail "$board" -p tv:windowStartS --count 1 >/dev/null || true
done

say "5. The HRV observations: one per window, named <recording>/hrv/<start in s>."
tahvel list "$board" -p sosa:observedProperty -o tv:HeartRateVariability --cascade 1
echo
echo "   The first window with its results (its links to RR items are left out here: step 7)."
show "$BIN/tahvel" list "$board" -s "$recording/hrv/0" --format ttl
first=$("$BIN/tahvel" list "$board" -s "$recording/hrv/0" --format ttl)
grep -v -e '/rr/' -e '^@prefix' -e '^$' <<<"$first" | sed 's/^/    /'
echo "    ... and prov:wasDerivedFrom $(grep -c '/rr/' <<<"$first") RR items."

if [ -f "$record.hea" ]; then
  say "6. The same record through 'tahvel hrv' (the chain in one process): the same numbers."
  tahvel hrv "$record"
fi

# The last IRI under $2 that $1 was derived from.
derived_from() {
  "$BIN/tahvel" list "$board" -s "$1" -p prov:wasDerivedFrom | grep -o "<$2[0-9]*>" | tail -1 | tr -d '<>'
}
say "7. Provenance, followed one link at a time: window -> RR item -> R-peak item -> ECG chunk."
rr=$(derived_from "$recording/hrv/0" "$recording/rr/")
rpeaks=$(derived_from "$rr" "$recording/rpeaks/")
chunk=$(derived_from "$rpeaks" "$recording/chunk/")
echo "   An RR item of the first window: its intervals (start end nn, in samples) and sources."
tahvel list "$board" -s "$rr" --format ttl | grep -v '^@prefix'
echo "   One of those R-peak items: the peaks decided while reading one chunk."
tahvel list "$board" -s "$rpeaks" --format ttl | grep -v '^@prefix'
echo "   And that chunk (its samples, base64, left out)."
show "$BIN/tahvel" list "$board" -s "$chunk" --format ttl
"$BIN/tahvel" list "$board" -s "$chunk" --format ttl | grep -v -e '^@prefix' -e 'tv:samples' -e '^\s*"'

say "8. Stop the agents (SIGTERM: each finishes its current item and exits)."
for pid in "${pids[@]}"; do kill -TERM "$pid"; done
wait
pids=()
for name in tahvel-rpeak tahvel-rr tahvel-hrv; do
  echo "   $(tail -1 "$work/$name.log")"
done

say "Done: the demo directory is removed."
