// How far a name is from another, for the "did you mean" of a misspelt term: the CLI's
// vocabulary warnings and the reasoner's datatypes.
//
//   uri::edit_distance("integr", "integer") == 1
#pragma once

#include <cstddef>
#include <string_view>

namespace tahvel::uri {

// How many one-character edits (a character dropped, added or changed, or two neighbours
// swapped) a slip is away from `a` to `b`, in bytes: the optimal string alignment distance.
std::size_t edit_distance(std::string_view a, std::string_view b);

}  // namespace tahvel::uri
