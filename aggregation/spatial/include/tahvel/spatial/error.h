// The one error type of Tahvel::spatial: a message naming the cause and the place, ready to
// print after "tahvel: ". WKT syntax errors also carry the 1-based column (byte offset + 1 in
// the text given to the parser) that the message names.
#pragma once

#include <cstddef>
#include <string>
#include <utility>

#include "tahvel/uri/expected.h"

namespace tahvel::spatial {

struct Error {
  std::string message;
  std::size_t column = 0;  // WKT errors: 1-based column of the offending character; else 0
};

template <class T>
using Result = Expected<T, Error>;

inline Unexpected<Error> fail(std::string message, std::size_t column = 0) {
  return {Error{std::move(message), column}};
}

}  // namespace tahvel::spatial
