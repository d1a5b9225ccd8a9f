#!/usr/bin/env bash
# Smoke test of `tahvel bench federation --quick --json` (label bench): the bench runs end to end
# in a private network namespace (tests/tools/netns-run), prints one JSON object with every
# figure issue 4 asks for as a number, and nothing was lost or duplicated. It asserts nothing
# about speed (STYLE 8): the figures are for people to judge. Also: outside a namespace the
# bench refuses to run and says how to run it.
# Usage: federation_smoke.sh TAHVEL NETNS_RUN
set -euo pipefail
tahvel=$1
netns_run=$2

refusal=$(env -u TAHVEL_IN_NETNS "$tahvel" bench federation --quick --json 2>&1) && {
  echo "FAIL: the bench ran outside a network namespace"; exit 1; }
grep -q "netns-run" <<<"$refusal" || { echo "FAIL: the refusal does not say how to run it: $refusal"; exit 1; }

out=$("$netns_run" "$tahvel" bench federation --quick --json)
echo "$out"
[[ ${out:0:1} == "{" ]] || { echo "FAIL: output is not one JSON object"; exit 1; }
value() {  # the number after "key": in the flat JSON object, or nothing
  sed -n "s/^ *\"$1\": *\(-\{0,1\}[0-9][0-9.eE+-]*\),\{0,1\}$/\1/p" <<<"$out"
}
status=0
for key in dds_up_p50_us dds_up_p99_us lcm_up_p50_us lcm_up_p99_us dds_raw_p50_us lcm_raw_p50_us \
           dds_raw_p99_us lcm_raw_p99_us dds_raw_half_rtt_p50_us lcm_raw_half_rtt_p50_us dds_raw_half_rtt_p99_us lcm_raw_half_rtt_p99_us \
           dds_binding_p50_us lcm_binding_p50_us dds_link_items_per_s lcm_link_items_per_s dds_query_records_per_s dds_query_mb_per_s lcm_query_records_per_s lcm_query_mb_per_s \
           hospital_ingest_items_per_s hospital_ingest_in_process_items_per_s homes lost duplicated items_checked; do
  v=$(value "$key")
  if [[ -z $v ]]; then echo "FAIL: missing or not a number: $key"; status=1; fi
done
[[ $(value lost) == 0 ]] || { echo "FAIL: lost = $(value lost)"; status=1; }
[[ $(value duplicated) == 0 ]] || { echo "FAIL: duplicated = $(value duplicated)"; status=1; }
[[ $(value items_checked) != 0 ]] || { echo "FAIL: no items were checked"; status=1; }
# The floors' legs are timed with the echo's clock, this machine's: every round gives two.
for k in dds lcm; do
  [[ $(value ${k}_raw_legs) != 0 && -n $(value ${k}_raw_legs) ]] || { echo "FAIL: no one-way legs of the $k floor"; status=1; }
done
exit $status
