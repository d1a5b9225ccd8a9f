// Frame checks and drop-line wording shared by the LCM and DDS bindings.
#include "wire_common.h"

#include <chrono>
#include <cstdio>
#include <memory>
#include <mutex>

#include "tahvel/node/term.h"

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

std::string one_line(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  auto escape = [&out](unsigned char c) {
    char buf[5];
    std::snprintf(buf, sizeof buf, "\\x%02x", c);
    out += buf;
  };
  while (!text.empty()) {
    const std::size_t bad = node::ill_formed_utf8_at(text);
    const std::string_view good = text.substr(0, bad);
    for (std::size_t i = 0; i < good.size(); ++i) {
      const auto c = static_cast<unsigned char>(good[i]);
      const bool c1 = c == 0xc2 && i + 1 < good.size() && static_cast<unsigned char>(good[i + 1]) < 0xa0;  // U+0080-U+009F
      if (c < 0x20 || c == 0x7f) {
        escape(c);
      } else if (c1) {
        escape(c);
        escape(static_cast<unsigned char>(good[++i]));
      } else {
        out += static_cast<char>(c);
      }
    }
    if (bad == std::string_view::npos) break;
    escape(static_cast<unsigned char>(text[bad]));
    text.remove_prefix(bad + 1);
  }
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

namespace {

void put_le(std::string& out, std::uint64_t value, int bytes) {
  for (int i = 0; i < bytes; ++i) out.push_back(static_cast<char>((value >> (8 * i)) & 0xff));
}

std::uint64_t get_le(std::string_view in, std::size_t pos, int bytes) {
  std::uint64_t value = 0;
  for (int i = 0; i < bytes; ++i) value |= std::uint64_t{static_cast<unsigned char>(in[pos + i])} << (8 * i);
  return value;
}

}  // namespace

void append_packed(std::string& pack, const Frame& frame) {
  put_le(pack, static_cast<std::uint8_t>(frame.kind), 1);
  put_le(pack, frame.seq, 8);
  put_le(pack, frame.prev, 8);
  put_le(pack, frame.ack, 8);
  put_le(pack, frame.body.size(), 4);
  pack.append(frame.body);
}

std::vector<Frame> unpack(const Frame& sample, std::string& error) {
  std::vector<Frame> frames;
  const std::string_view in(sample.body);
  std::size_t pos = 0;
  while (pos < in.size()) {
    if (in.size() - pos < kPackedFrameHeader) {
      error = "packed frame " + std::to_string(frames.size() + 1) + " truncated in its header at byte " +
              std::to_string(pos) + " of " + std::to_string(in.size());
      return frames;
    }
    Frame f;
    f.version = sample.version;
    f.fingerprint = sample.fingerprint;
    f.from = sample.from;
    f.to = sample.to;
    f.kind = static_cast<FrameKind>(get_le(in, pos, 1));
    f.seq = get_le(in, pos + 1, 8);
    f.prev = get_le(in, pos + 9, 8);
    f.ack = get_le(in, pos + 17, 8);
    const std::uint64_t size = get_le(in, pos + 25, 4);
    pos += kPackedFrameHeader;
    if (size > in.size() - pos) {
      error = "packed frame " + std::to_string(frames.size() + 1) + " says its body has " + std::to_string(size) +
              " bytes, " + std::to_string(in.size() - pos) + " are left";
      return frames;
    }
    f.body.assign(in.substr(pos, size));
    pos += size;
    frames.push_back(std::move(f));
  }
  if (frames.size() != sample.seq) {  // which of them to believe? none
    error = "the sample says it packs " + std::to_string(sample.seq) + " frames, it holds " + std::to_string(frames.size());
    frames.clear();
  }
  return frames;
}

DropLog rate_limited(DropLog log) {
  struct Budget {
    std::mutex mu;
    std::chrono::steady_clock::time_point window_start{};
    std::size_t said = 0, left_out = 0;
  };
  return [log = std::move(log), budget = std::make_shared<Budget>()](std::string_view line) {
    std::size_t left_out = 0;
    {
      std::lock_guard lock(budget->mu);
      const auto now = std::chrono::steady_clock::now();
      if (now - budget->window_start >= kDropLogWindow) {
        left_out = budget->left_out;
        budget->window_start = now;
        budget->said = 0;
        budget->left_out = 0;
      }
      if (budget->said == kDropLinesPerWindow) {
        ++budget->left_out;
        return;
      }
      ++budget->said;
    }
    if (left_out > 0)
      log(std::to_string(left_out) + " more dropped frame" + (left_out == 1 ? " was" : "s were") + " not logged (at most " +
          std::to_string(kDropLinesPerWindow) + " lines per " + std::to_string(kDropLogWindow.count()) + " s)");
    log(line);
  };
}

DropLog or_stderr(DropLog log) {
  if (log) return log;
  return [](std::string_view line) {
    std::fprintf(stderr, "tahvel: %.*s\n", static_cast<int>(line.size()), line.data());
  };
}

}  // namespace tahvel::federation::wire
