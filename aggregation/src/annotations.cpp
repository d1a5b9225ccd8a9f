// MIT-format annotation decoding. The whole file is read into memory first (a few kilobytes
// for MIT-BIH), then walked word by word, so every error can name a byte offset.
#include "tahvel/aggregation/annotations.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <string_view>

namespace tahvel::aggregation {

namespace {

constexpr int kSkip = 59, kNum = 60, kSub = 61, kChn = 62, kAux = 63;
constexpr int kNoise = 14, kNote = 22, kVfOn = 32, kVfOff = 33;

// Index = WFDB annotation code (ecgcodes.h); 0 where WFDB has no one-character mnemonic.
constexpr std::array<char, 50> kCodes = {
    ' ', 'N', 'L', 'R', 'a', 'V', 'F', 'J', 'A', 'S',  //  0 -  9
    'E', 'j', '/', 'Q', '~', 0,   '|', 0,   's', 'T',  // 10 - 19
    '*', 'D', '"', '=', 'p', 'B', '^', 't', '+', 'u',  // 20 - 29
    '?', '!', '[', ']', 'e', 'n', '@', 'x', 'f', '(',  // 30 - 39
    ')', 'r', 0,   0,   0,   0,   0,   0,   0,   0,    // 40 - 49
};

// A little cursor over the file bytes that reports where it ran out.
struct Cursor {
  const std::vector<unsigned char>& bytes;
  std::size_t pos = 0;
  bool has(std::size_t n) const { return bytes.size() - pos >= n; }
  unsigned word() {  // caller checked has(2)
    unsigned w = bytes[pos] | (bytes[pos + 1] << 8);
    pos += 2;
    return w;
  }
};

std::string at(const std::string& file, std::size_t offset) {
  return file + ": byte " + std::to_string(offset) + ": ";
}

}  // namespace

char annotation_code(int type) {
  return type >= 0 && type < static_cast<int>(kCodes.size()) ? kCodes[static_cast<std::size_t>(type)]
                                                             : char{0};
}

int annotation_type(char code) {
  if (code == 0) return -1;
  if (code == '`') return 39;
  if (code == '\'') return 40;
  for (std::size_t i = 0; i < kCodes.size(); ++i)
    if (kCodes[i] == code) return static_cast<int>(i);
  return -1;
}

bool is_beat(char code) {
  switch (code) {
    case 'N': case 'L': case 'R': case 'B': case 'A': case 'a': case 'J': case 'S': case 'V':
    case 'r': case 'F': case 'e': case 'j': case 'n': case 'E': case '/': case 'f': case 'Q':
    case '?':
      return true;
    default:
      return false;
  }
}

Result<std::vector<Annotation>> read_annotations(const std::string& record_path,
                                                 const std::string& annotator, double record_fs) {
  const std::string file = record_path + "." + annotator;
  std::ifstream in(file, std::ios::binary);
  if (!in) return fail(file + ": cannot open annotation file: " + std::strerror(errno));
  // A directory opens, and its first read throws from inside the stream buffer: an "internal
  // error" that stopped `tahvel hrv --eval` over several records at that one.
  std::vector<unsigned char> bytes;
  try {
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  } catch (const std::exception&) {
    return fail(file + ": cannot read annotation file: " + std::strerror(errno ? errno : EIO));
  }
  if (in.bad()) return fail(file + ": cannot read annotation file: " + std::strerror(errno ? errno : EIO));

  std::vector<Annotation> out;
  Cursor c{bytes};
  std::int64_t time = 0;
  int chan = 0, num = 0;
  for (;;) {
    std::size_t here = c.pos;
    if (!c.has(2)) {
      return fail(at(file, here) + (c.has(1) ? "truncated inside a word"
                                            : "truncated: no end-of-file word after " +
                                                  std::to_string(out.size()) + " annotations"));
    }
    unsigned w = c.word();
    int a = static_cast<int>(w >> 10);
    unsigned i = w & 0x3FF;
    if (w == 0) break;  // logical end of file
    switch (a) {
      case kSkip: {
        if (!c.has(4)) return fail(at(file, here) + "truncated inside a SKIP interval");
        unsigned hi = c.word(), lo = c.word();
        auto delta = static_cast<std::int32_t>((hi << 16) | lo);
        time += delta;
        if (time < 0) return fail(at(file, here) + "SKIP makes the time negative");
        break;
      }
      case kNum:
      case kSub:
      case kChn:
      case kAux: {
        if (out.empty())
          return fail(at(file, here) + "NUM/SUB/CHN/AUX word before the first annotation");
        Annotation& last = out.back();
        if (a == kNum) last.num = num = static_cast<int>(i);
        if (a == kSub) last.subtype = static_cast<int>(i);
        if (a == kChn) last.chan = chan = static_cast<int>(i);
        if (a == kAux) {
          std::size_t len = i & 0xFF, padded = (len + 1) & ~std::size_t{1};
          if (!c.has(padded))
            return fail(at(file, here) + "truncated inside " + std::to_string(len) +
                        " AUX bytes");
          last.aux.assign(reinterpret_cast<const char*>(&bytes[c.pos]), len);
          while (!last.aux.empty() && last.aux.back() == '\0') last.aux.pop_back();
          c.pos += padded;
        }
        break;
      }
      default: {
        // Types 50..58 have no meaning in ecgcodes.h, but WFDB's getann reads them as annotations
        // of that type (their code is 0: no beat, nothing scored).
        time += i;
        // An annotation file is in time order (WFDB's writer sorts what it was given when it
        // closes the file); a negative SKIP that goes back would make beats match nothing,
        // scored as misses and false ones.
        if (!out.empty() && time < out.back().sample)
          return fail(at(file, here) + "annotation at sample " + std::to_string(time) + " comes after one at sample " +
                      std::to_string(out.back().sample) + ": annotations must be in time order");
        Annotation ann;
        ann.sample = time;
        ann.type = a;
        ann.code = annotation_code(a);
        ann.chan = chan;
        ann.num = num;
        out.push_back(std::move(ann));
      }
    }
  }
  // WFDB 10.5's "## time resolution: F" note (a NOTE at time 0, as setafreq writes it): the
  // times are in units of 1/F s, which getann converts to the record's samples.
  for (const Annotation& a : out) {
    if (a.sample != 0) break;
    constexpr std::string_view kResolution = "## time resolution: ";
    if (a.type != kNote || !a.aux.starts_with(kResolution)) continue;
    const std::string text = a.aux.substr(kResolution.size());
    char* end = nullptr;
    const double f = std::strtod(text.c_str(), &end);
    if (end == text.c_str() || !std::isfinite(f) || f <= 0)
      return fail(file + ": the time resolution note '" + a.aux + "' does not give a frequency above 0");
    if (record_fs <= 0) break;  // the caller does not use the times
    if (f != record_fs)
      for (Annotation& b : out) b.sample = std::llround(static_cast<double>(b.sample) * record_fs / f);
    break;
  }
  return out;
}

namespace {

template <class Opens, class Closes>
std::vector<std::pair<std::int64_t, std::int64_t>> intervals(const std::vector<Annotation>& anns,
                                                             std::int64_t record_end, Opens opens,
                                                             Closes closes) {
  std::vector<std::pair<std::int64_t, std::int64_t>> out;
  bool open = false;
  std::int64_t from = 0;
  for (const Annotation& a : anns) {
    if (open && closes(a)) {
      out.emplace_back(from, a.sample);
      open = false;
    } else if (!open && opens(a)) {
      from = a.sample;
      open = true;
    }
  }
  if (open) out.emplace_back(from, std::max(from, record_end));
  return out;
}

}  // namespace

std::vector<std::pair<std::int64_t, std::int64_t>> unreadable_intervals(
    const std::vector<Annotation>& annotations, std::int64_t record_end) {
  return intervals(
      annotations, record_end,
      [](const Annotation& a) { return a.type == kNoise && (a.subtype & 0x30) == 0x30; },
      [](const Annotation& a) { return a.type == kNoise; });
}

std::optional<UnclosedUnreadable> unclosed_unreadable(const std::vector<Annotation>& annotations) {
  const std::vector<std::pair<std::int64_t, std::int64_t>> intervals = unreadable_intervals(annotations, 0);
  if (intervals.empty()) return std::nullopt;
  // Left open when no '~' follows the last interval's marker; beats after the marker count.
  const std::int64_t opened = intervals.back().first;
  bool marker_seen = false;
  UnclosedUnreadable open{opened, 0};
  for (const Annotation& a : annotations) {
    if (a.sample < opened) continue;
    if (!marker_seen) {
      marker_seen = a.type == kNoise && (a.subtype & 0x30) == 0x30;
      continue;
    }
    if (a.type == kNoise) return std::nullopt;
    if (is_beat(a.code)) ++open.beats_after;
  }
  if (open.beats_after == 0) return std::nullopt;
  return open;
}

std::vector<std::pair<std::int64_t, std::int64_t>> flutter_intervals(
    const std::vector<Annotation>& annotations, std::int64_t record_end) {
  return intervals(
      annotations, record_end, [](const Annotation& a) { return a.type == kVfOn; },
      [](const Annotation& a) { return a.type == kVfOff; });
}

}  // namespace tahvel::aggregation
