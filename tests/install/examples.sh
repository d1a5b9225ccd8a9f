# shellcheck shell=bash
# shellcheck disable=SC2154  # src, work, cc, cxx and flags are the caller's
# Sourced by check_install.sh and check_uninstalled.sh: builds both example agents with the
# pkg-config flags `flags` and runs them against a store made by `tahvel` (the program given);
# the item each derives must be on the board, written as its agent. Needs src, work, cc, cxx and
# fail() set by the caller; `against` names the tree in the failure messages.
build_and_run_examples() {
  local tahvel=$1 against=$2
  # shellcheck disable=SC2086  # the flags are words
  "$cc" -std=c99 -o "$work/example_agent" "$src/agents/examples/example_agent.c" $flags ||
    fail "the C example does not build against $against"
  # shellcheck disable=SC2086
  "$cxx" -std=c++20 -o "$work/example_agent_cpp" "$src/agents/examples/example_agent_cpp.cpp" $flags ||
    fail "the C++ example does not build against $against"
  local store=$work/home1
  "$tahvel" init "$store" --iri http://example.org/home1
  # A first run of each writes its subscription (persistent), which later items are routed by.
  "$work/example_agent" "$store" --idle 1 > /dev/null 2>&1 || fail "the C example built against $against failed"
  "$work/example_agent_cpp" "$store" --idle 1 > /dev/null 2>&1 || fail "the C++ example built against $against failed"
  "$tahvel" put "$store" > /dev/null <<'TTL'
<http://example.org/home1/obs/17> <https://w3id.org/tahvel#heartRate> "112"^^<http://www.w3.org/2001/XMLSchema#integer> .
TTL
  "$work/example_agent" "$store" --count 1 --idle 10 > /dev/null || fail "the C example built against $against failed"
  "$work/example_agent_cpp" "$store" --count 1 --idle 10 > /dev/null || fail "the C++ example built against $against failed"
  local agent out
  for agent in example-c example-cpp; do
    out=$("$tahvel" list "$store" --source "http://example.org/home1/$agent" -p https://w3id.org/tahvel#heartRateClass)
    [[ $out == *'"high"'* ]] || fail "no heartRateClass \"high\" from $agent on the board: $out"
  done
}
