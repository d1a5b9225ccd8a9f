// The node library's one error set. Every fallible call returns Result<T> (= Expected<T, Error>)
// and promises that the store is unchanged when it fails: a failed write leaves nothing behind.
#pragma once

#include <string>

#include "tahvel/uri/expected.h"

namespace tahvel::node {

enum class Errc {
  invalid_argument = 1,  // a bad parameter (a literal subject, unbound pattern where one is required, ...)
  invalid_iri,           // an IRI that does not parse; message names the position
  syntax,                // N-Triples/Turtle/JSON input error; message names line and column
  literal_too_large,     // a literal over the node's limit; message names the triple and sizes
  store_full,            // the LMDB map reached its configured maximum and could not grow
  not_found,             // no such node directory, item, agent or record
  exists,                // init of a directory that already holds a store
  io,                    // an operating-system error (message carries strerror and the path)
  corrupt,               // the store's contents are not what this version wrote
  timeout,               // a wait ended without the awaited event
  version,               // the store was written by an incompatible format version
};

struct Error {
  Errc code;
  std::string message;  // one line naming cause and place, ready to print after "tahvel: "
};

template <class T>
using Result = Expected<T, Error>;

// Short, stable name of an error code ("store_full").
const char* errc_name(Errc code) noexcept;

inline Unexpected<Error> fail(Errc code, std::string message) {
  return {Error{code, std::move(message)}};
}

}  // namespace tahvel::node
