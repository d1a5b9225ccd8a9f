#!/usr/bin/env bash
# Checks that deploy/tahvel/vocabulary.cpp lists exactly the tv: terms (https://w3id.org/tahvel#)
# that the sources, deploy files and docs use, sorted: `tahvel up` warns about a forwarding
# pattern naming a term outside the list, so a term added anywhere must be added there.
# Usage: check_vocabulary.sh SOURCE_DIR     (exit 0 clean, 1 with what differs)
set -u
root=${1:?usage: check_vocabulary.sh SOURCE_DIR}
cd "$root" || exit 2
list=deploy/tahvel/vocabulary.cpp
used=$(
  {
    grep -rhoE --exclude=vocabulary.cpp "tv:[A-Za-z][A-Za-z0-9]*" uri node agents aggregation federation deploy docs | sed 's/^tv://'
    grep -rhoE --exclude=vocabulary.cpp "w3id\.org/tahvel#[A-Za-z][A-Za-z0-9]*" uri node agents aggregation federation deploy docs | sed 's/.*#//'
    grep -rhoE --exclude=vocabulary.cpp '(kTv|kTahvelNs)\)? *\+ *"[A-Za-z][A-Za-z0-9]*"' uri node agents aggregation federation deploy | sed -E 's/.*"(.*)"/\1/'
  } | LC_ALL=C sort -u
)
listed=$(grep -oE '^    std::string_view\("[A-Za-z0-9]+"\),$' "$list" | sed -E 's/.*"(.*)".*/\1/')
status=0
if [ "$listed" != "$(LC_ALL=C sort -u <<<"$listed")" ]; then
  echo "$list: the terms are not sorted (LC_ALL=C) or repeat one"
  status=1
fi
missing=$(LC_ALL=C comm -23 <(echo "$used") <(LC_ALL=C sort -u <<<"$listed"))
extra=$(LC_ALL=C comm -13 <(echo "$used") <(LC_ALL=C sort -u <<<"$listed"))
[ -n "$missing" ] && { echo "used but not in $list:"; echo "$missing" | sed 's/^/  tv:/'; status=1; }
[ -n "$extra" ] && { echo "in $list but used nowhere:"; echo "$extra" | sed 's/^/  tv:/'; status=1; }
exit $status
