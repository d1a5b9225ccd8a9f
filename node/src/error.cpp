// Names of the node library's error codes, for messages and logs ("store_full"). They are part
// of the interface: scripts match on them, so a name never changes once released.
#include "tahvel/node/error.h"

namespace tahvel::node {

const char* errc_name(Errc code) noexcept {
  switch (code) {
    case Errc::invalid_argument: return "invalid_argument";
    case Errc::invalid_iri: return "invalid_iri";
    case Errc::syntax: return "syntax";
    case Errc::literal_too_large: return "literal_too_large";
    case Errc::store_full: return "store_full";
    case Errc::not_found: return "not_found";
    case Errc::exists: return "exists";
    case Errc::io: return "io";
    case Errc::corrupt: return "corrupt";
    case Errc::timeout: return "timeout";
    case Errc::version: return "version";
  }
  return "unknown";  // a value outside the enumeration (a cast from a stale integer)
}

}  // namespace tahvel::node
