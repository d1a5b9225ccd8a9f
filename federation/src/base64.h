// Base64 (RFC 4648, with padding) for answer chunks written on the board as xsd:base64Binary.
#pragma once

#include <optional>
#include <string>
#include <string_view>

namespace tahvel::federation::detail {

std::string base64_encode(std::string_view bytes);
std::optional<std::string> base64_decode(std::string_view text);  // nullopt: not base64

}  // namespace tahvel::federation::detail
