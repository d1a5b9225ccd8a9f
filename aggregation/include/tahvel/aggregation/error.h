// The error type of Tahvel::dsp: one message naming the cause and the place (file, field,
// line, sample), ready to print after "tahvel: ". Functions that cannot fail return values.
#pragma once

#include <string>
#include <utility>

#include "tahvel/uri/expected.h"

namespace tahvel::aggregation {

struct Error {
  std::string message;
};

template <class T>
using Result = Expected<T, Error>;

inline Unexpected<Error> fail(std::string message) { return {Error{std::move(message)}}; }

}  // namespace tahvel::aggregation
