#!/usr/bin/env bash
# Checks that dependencies point one way (DESIGN §9): uri <- node <- agents, aggregation,
# federation, deploy; and that nothing outside a component includes that component's src/.
# Usage: check_includes.sh SOURCE_DIR     (exit 0 clean, 1 with one line per offence)
set -u
root=${1:?usage: check_includes.sh SOURCE_DIR}
cd "$root" || exit 2
status=0
offend() { echo "$1"; status=1; }

# What each component may include of Tahvel's own headers (its own, and those below it).
allowed() {
  case "$1" in
    uri) echo "uri" ;;
    node) echo "uri node" ;;
    deploy) echo "uri node agents aggregation spatial federation" ;;  # the command uses everything
    aggregation) echo "uri node aggregation spatial" ;;  # spatial/ is a library inside it
    *) echo "uri node $1" ;;  # agents, aggregation, federation: node's API, not each other
  esac
}

for component in uri node agents aggregation federation deploy; do
  [ -d "$component" ] || continue
  ok=$(allowed "$component")
  while IFS=: read -r file line text; do
    dep=$(sed -E 's|.*"tahvel/([a-z_]+)/.*|\1|' <<<"$text")
    case " $ok " in
      *" $dep "*) ;;
      *) offend "$file:$line: $component may not include tahvel/$dep/ ($text)" ;;
    esac
  done < <(grep -rnE '#include "tahvel/[a-z_]+/' "$component" --include='*.h' --include='*.c' --include='*.cpp' || true)
done

# Private headers: "<component>/src/..." or ../src/ from outside the component.
while IFS=: read -r file line text; do
  offend "$file:$line: includes another component's private src/ ($text)"
done < <(grep -rnE '#include "[^"]*(uri|node|agents|aggregation|federation)/src/' \
           uri node agents aggregation federation deploy tests 2>/dev/null || true)

exit $status
