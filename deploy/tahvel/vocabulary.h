// The terms of the tv: vocabulary (https://w3id.org/tahvel#, docs/vocabulary.md) that Tahvel's
// programs, deploy files and docs use: what a topology file's patterns can expect to match.
// tests/hygiene/check_vocabulary.sh fails when a term is used and not listed here.
#pragma once

#include <cstddef>
#include <optional>
#include <string_view>

#include "tahvel/uri/spelling.h"

namespace tahvel::cli {

using uri::edit_distance;

// Whether `local_name` (the part after "tv:") is a term of the vocabulary.
bool is_tahvel_term(std::string_view local_name);

// The term nearest to `local_name` within three edits (a misspelling), if any.
std::optional<std::string_view> nearest_tahvel_term(std::string_view local_name);

// For a name after "sosa:" that is not a SOSA term: the term it is within two edits of (a
// misspelling, "observedPropery"), if any. Null for a term and for a name near none.
std::optional<std::string_view> sosa_term_misspelt(std::string_view local_name);

}  // namespace tahvel::cli
