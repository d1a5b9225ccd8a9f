// Frame checks and drop-line wording shared by the LCM and DDS bindings.
#include "wire_common.h"

#include <cstdio>

namespace tahvel::federation::wire {

bool known_kind(std::uint8_t kind) noexcept {
  return kind >= static_cast<std::uint8_t>(FrameKind::hello) &&
         kind <= static_cast<std::uint8_t>(FrameKind::heartbeat);
}

std::string printable(std::string_view text, std::size_t max) {
  std::string out;
  for (std::size_t i = 0; i < text.size() && i < max; ++i) {
    auto c = static_cast<unsigned char>(text[i]);
    if (c >= 0x20 && c < 0x7f) {
      out += static_cast<char>(c);
    } else {
      char buf[5];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    }
  }
  if (text.size() > max) out += "...";
  return out;
}

std::string describe(const Frame& frame) {
  return "kind " + std::to_string(static_cast<unsigned>(frame.kind)) + " seq " +
         std::to_string(frame.seq) + " from <" + printable(frame.from) + "> to <" +
         printable(frame.to) + ">";
}

Result<void> check_sendable(const Frame& frame, std::string_view binding, std::string_view self) {
  auto refuse = [&](const std::string& why) {
    return node::fail(Errc::invalid_argument,
                      std::string(binding) + " <" + std::string(self) + "> send (" + describe(frame) + "): " + why);
  };
  if (frame.to.empty()) return refuse("empty `to` IRI");
  if (frame.to.find('\0') != std::string::npos || frame.from.find('\0') != std::string::npos)
    return refuse("an IRI contains a NUL byte");
  if (frame.body.size() > kMaxBody)
    return refuse("body of " + std::to_string(frame.body.size()) + " bytes is over the limit of " +
                  std::to_string(kMaxBody));
  return {};
}

std::optional<std::string> reject_reason(const Frame& frame, std::string_view self) {
  // The rule every binding shares (frame_refusal in frame.cpp), made safe for one log line:
  // the IRIs in it came from the wire.
  if (auto why = frame_refusal(frame, self)) return printable(*why, 600);
  const auto kind = static_cast<std::uint8_t>(frame.kind);
  if (!known_kind(kind)) return "frame kind " + std::to_string(kind) + " unknown";
  return std::nullopt;
}

DropLog or_stderr(DropLog log) {
  if (log) return log;
  return [](std::string_view line) {
    std::fprintf(stderr, "tahvel: %.*s\n", static_cast<int>(line.size()), line.data());
  };
}

}  // namespace tahvel::federation::wire
