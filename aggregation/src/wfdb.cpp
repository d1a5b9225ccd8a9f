// WFDB header parsing and signal decoding (the formats of signal(5): 8, 16, 24, 32, 61, 80, 160,
// 212, 310, 311). The header parser is a small
// field-by-field reader so that every error can name the file, line and field; the decoders
// work on whole byte blocks so a 30-minute MIT-BIH record decodes in one pass.
#include "tahvel/aggregation/wfdb.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <cstdio>
#include <sstream>
#include <system_error>

namespace tahvel::aggregation {

namespace {

// ---- small text helpers ----

std::string_view trim(std::string_view s) {
  const char* blanks = " \t\r\n\f\v";
  auto b = s.find_first_not_of(blanks);
  if (b == std::string_view::npos) return {};
  auto e = s.find_last_not_of(blanks);
  return s.substr(b, e - b + 1);
}

// Splits on blanks; also returns where each token starts, so the description (the rest of a
// signal line) can be taken verbatim.
struct Tokens {
  std::vector<std::string_view> items;
  std::vector<std::size_t> starts;
};

Tokens tokenize(std::string_view line) {
  Tokens t;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    if (i >= line.size()) break;
    std::size_t b = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
    t.items.push_back(line.substr(b, i - b));
    t.starts.push_back(b);
  }
  return t;
}

template <class Int>
bool parse_int(std::string_view s, Int& out) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  if (s.empty()) return false;
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && p == s.data() + s.size();
}

// Why `s` did not parse as an Int: a number of digits beyond Int's range is said to be so (a
// sample count of 10^20 was "not a non-negative integer"); anything else gets `otherwise`.
template <class Int>
std::string not_int_because(std::string_view s, const char* otherwise) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);  // a negative number is not non-negative
  if (!s.empty() && s.find_first_not_of("0123456789") == std::string_view::npos)
    return "out of range: at most " + std::to_string(std::numeric_limits<Int>::max());
  return otherwise;
}

bool parse_double(std::string_view s, double& out) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  if (s.empty()) return false;
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && p == s.data() + s.size() && std::isfinite(out);
}

// Error context for one header line.
struct Where {
  const std::string& file;
  int line;
  std::string field_error(const char* field, std::string_view value, const std::string& why) const {
    std::ostringstream m;
    m << file << ":" << line << ": field '" << field << "' ('";
    // A control character (a lone carriage return left by an editor) is shown as \xNN: printed
    // raw, it made a valid-looking value the one at fault ('650000' on a terminal).
    for (char c : value) {
      if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
        char escaped[8];
        std::snprintf(escaped, sizeof escaped, "\\x%02X", static_cast<unsigned char>(c));
        m << escaped;
      } else {
        m << c;
      }
    }
    m << "'): " << why;
    return m.str();
  }
};

// ---- record line: name[/nseg] nsig [fs[/counterfreq][(base)]] [nsamp] [time] [date] ----

// A whole number of at most `digits` digits, at most `max`.
bool is_number_up_to(std::string_view s, std::size_t digits, int max) {
  if (s.empty() || s.size() > digits) return false;
  int v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
    v = v * 10 + (c - '0');
  }
  return v <= max;
}

// WFDB's base time: [[HH:]MM:]SS[.sss], hours as many as the recording began after midnight.
bool is_base_time(std::string_view s) {
  std::vector<std::string_view> parts;
  for (std::size_t from = 0;;) {
    const std::size_t colon = s.find(':', from);
    parts.push_back(s.substr(from, colon == std::string_view::npos ? colon : colon - from));
    if (colon == std::string_view::npos) break;
    from = colon + 1;
  }
  if (parts.size() > 3) return false;
  std::string_view seconds = parts.back();
  if (const std::size_t dot = seconds.find('.'); dot != std::string_view::npos) {
    if (!is_number_up_to(seconds.substr(dot + 1), 9, 999'999'999)) return false;
    seconds = seconds.substr(0, dot);
  }
  if (!is_number_up_to(seconds, 2, 60)) return false;
  if (parts.size() >= 2 && !is_number_up_to(parts[parts.size() - 2], 2, 59)) return false;
  return parts.size() < 3 || is_number_up_to(parts[0], 4, 9999);
}

// WFDB's base date: DD/MM/YYYY.
bool is_base_date(std::string_view s) {
  const std::size_t a = s.find('/'), b = a == std::string_view::npos ? a : s.find('/', a + 1);
  if (b == std::string_view::npos) return false;
  std::string_view day = s.substr(0, a), month = s.substr(a + 1, b - a - 1), year = s.substr(b + 1);
  return is_number_up_to(day, 2, 31) && day != "0" && day != "00" && is_number_up_to(month, 2, 12) &&
         month != "0" && month != "00" && is_number_up_to(year, 4, 9999);
}

Result<bool> parse_record_line(std::string_view line, const Where& at, RecordHeader& h) {
  Tokens t = tokenize(line);
  if (t.items.size() < 2)
    return fail(at.file + ":" + std::to_string(at.line) +
                ": record line needs at least a name and a signal count");
  std::string_view name = t.items[0];
  if (name.find('/') != std::string_view::npos)
    return fail(at.field_error("record name", name,
                               "multi-segment records are not supported"));
  h.name = std::string(name);
  if (!parse_int(t.items[1], h.signal_count) || h.signal_count < 0)
    return fail(at.field_error("number of signals", t.items[1], not_int_because<int>(t.items[1], "not a non-negative integer")));
  if (t.items.size() > 2) {
    std::string_view fs = t.items[2];
    // The counter frequency and base counter are not used, but a field that does not parse is
    // refused as any other (a header mangled there may be mangled elsewhere).
    if (const std::size_t cut = fs.find_first_of("/("); cut != std::string_view::npos) {
      std::string_view counter = fs.substr(cut);
      double v = 0;
      if (counter.front() == '/') {
        const std::size_t paren = counter.find('(');
        // Empty or not positive is allowed: WFDB then takes the sampling frequency.
        const std::string_view frequency = counter.substr(1, paren == std::string_view::npos ? paren : paren - 1);
        if (!frequency.empty() && !parse_double(frequency, v))
          return fail(at.field_error("sampling frequency", t.items[2], "the counter frequency after '/' is not a number"));
        counter.remove_prefix(paren == std::string_view::npos ? counter.size() : paren);
      }
      if (!counter.empty() &&
          (counter.front() != '(' || counter.back() != ')' || !parse_double(counter.substr(1, counter.size() - 2), v)))
        return fail(at.field_error("sampling frequency", t.items[2], "the base counter is not a number in parentheses"));
      fs = fs.substr(0, cut);
    }
    if (!parse_double(fs, h.fs) || h.fs <= 0)
      return fail(at.field_error("sampling frequency", t.items[2], "not a positive number"));
    if (h.fs > kMaxSamplingHz)
      return fail(at.field_error("sampling frequency", t.items[2], "more than 100000 Hz, the most this reader takes"));
    h.fs_given = true;
  }
  if (t.items.size() > 3) {
    if (!parse_int(t.items[3], h.samples_per_signal) || h.samples_per_signal < 0)
      return fail(at.field_error("number of samples per signal", t.items[3],
                                 not_int_because<std::int64_t>(t.items[3], "not a non-negative integer")));
  }
  // The base time and date are not used; checked so that a mangled record line is not read.
  if (t.items.size() > 4 && !is_base_time(t.items[4]))
    return fail(at.field_error("base time", t.items[4], "not a time of day [[HH:]MM:]SS[.s]"));
  if (t.items.size() > 5 && !is_base_date(t.items[5]))
    return fail(at.field_error("base date", t.items[5], "not a date DD/MM/YYYY"));
  return true;  // WFDB reads nothing after the date, and neither does this reader
}

// How a format packs values: `bytes` bytes hold `values` values, the signals of a file
// interleaved value by value. nullopt: not a format this reader decodes.
struct Packing {
  int bytes;
  int values;
};
std::optional<Packing> packing_of(int format) {
  switch (format) {
    case 8:    // 8-bit first differences
    case 80:   // 8-bit offset binary
      return Packing{1, 1};
    case 16:   // 16-bit two's complement, little-endian
    case 61:   // 16-bit two's complement, big-endian
    case 160:  // 16-bit offset binary
      return Packing{2, 1};
    case 212:  // two 12-bit values in 3 bytes
      return Packing{3, 2};
    case 24:
      return Packing{3, 1};
    case 32:
      return Packing{4, 1};
    case 310:  // three 10-bit values in 4 bytes (two 16-bit words)
    case 311:  // three 10-bit values in 4 bytes (one 32-bit word)
      return Packing{4, 3};
    default:
      return std::nullopt;
  }
}

// WFDB's ADC resolution when the header gives none: the bits a sample of the format holds.
int default_resolution(int format) {
  switch (format) {
    case 8: case 80: return 8;
    case 310: case 311: return 10;
    case 212: return 12;
    case 24: return 24;
    case 32: return 32;
    default: return 16;
  }
}

// ---- signal line: file format[xsamp][:skew][+offset] gain[(baseline)][/units] adcres adczero
//      initval checksum blocksize description ----

Result<bool> parse_format(std::string_view tok, const Where& at, SignalInfo& s) {
  std::size_t end = tok.find_first_of("x:+");
  if (!parse_int(tok.substr(0, end), s.format))
    return fail(at.field_error("format", tok, "not an integer"));
  while (end != std::string_view::npos) {
    char kind = tok[end];
    std::size_t next = tok.find_first_of("x:+", end + 1);
    std::string_view num = tok.substr(end + 1, next == std::string_view::npos ? next : next - end - 1);
    std::int64_t v = 0;
    if (!parse_int(num, v) || v < 0)
      return fail(at.field_error("format", tok, "bad sample-per-frame, skew or offset suffix"));
    if (kind == 'x' && v > 1)
      return fail(at.field_error("format", tok, "more than one sample per frame is not supported"));
    if (kind == ':' && v != 0)
      return fail(at.field_error("format", tok, "skew is not supported"));
    if (kind == '+') s.byte_offset = v;
    end = next;
  }
  if (s.format == 0) return true;  // a null signal: no file holds it (SignalReader gives no-values)
  if (!packing_of(s.format)) {
    // FLAC-compressed signal files (WFDB 10.7) are read by WFDB's own tools, which can write
    // them out again uncompressed.
    const bool flac = s.format == 508 || s.format == 516 || s.format == 524;
    return fail(at.field_error("format", tok,
                               "format " + std::to_string(s.format) +
                                   " is not supported (supported: 8, 16, 24, 32, 61, 80, 160, 212, 310, 311)" +
                                   (flac ? "; it is FLAC-compressed: write the record out uncompressed first (WFDB's "
                                           "xform, or wfdb-python's wrsamp, in format 16)"
                                         : "")));
  }
  return true;
}

Result<bool> parse_gain(std::string_view tok, const Where& at, SignalInfo& s, bool& has_baseline) {
  std::size_t slash = tok.find('/');
  if (slash != std::string_view::npos) {
    s.units = std::string(tok.substr(slash + 1));
    if (s.units.empty()) return fail(at.field_error("gain", tok, "empty units after '/'"));
    tok = tok.substr(0, slash);
  }
  std::size_t paren = tok.find('(');
  std::string_view g = tok.substr(0, paren);
  // A negative gain is a lead recorded upside down (WFDB reads it so); the detector takes
  // either polarity.
  if (!parse_double(g, s.gain) || !std::isfinite(s.gain))
    return fail(at.field_error("gain", tok, "not a number"));
  if (s.gain == 0) s.gain = 200;  // WFDB: 0 means "uncalibrated", read with the default gain
  if (paren != std::string_view::npos) {
    if (tok.back() != ')' || !parse_int(tok.substr(paren + 1, tok.size() - paren - 2), s.baseline))
      return fail(at.field_error("gain", tok, "baseline in parentheses is not an integer"));
    has_baseline = true;
  }
  return true;
}

Result<SignalInfo> parse_signal_line(std::string_view line, const Where& at) {
  Tokens t = tokenize(line);
  SignalInfo s;
  if (t.items.size() < 2)
    return fail(at.file + ":" + std::to_string(at.line) +
                ": signal line needs at least a file name and a format");
  s.file = std::string(t.items[0]);
  if (auto r = parse_format(t.items[1], at, s); !r) return fail(r.error().message);
  bool has_baseline = false, has_zero = false, has_init = false;
  if (t.items.size() > 2)
    if (auto r = parse_gain(t.items[2], at, s, has_baseline); !r) return fail(r.error().message);
  if (t.items.size() > 3 && (!parse_int(t.items[3], s.adc_resolution) || s.adc_resolution < 0))
    return fail(at.field_error("ADC resolution", t.items[3], not_int_because<int>(t.items[3], "not a non-negative integer")));
  if (t.items.size() > 4) {
    if (!parse_int(t.items[4], s.adc_zero))
      return fail(at.field_error("ADC zero", t.items[4], "not an integer"));
    has_zero = true;
  }
  if (t.items.size() > 5) {
    if (!parse_int(t.items[5], s.initial_value))
      return fail(at.field_error("initial value", t.items[5], "not an integer"));
    has_init = true;
  }
  if (t.items.size() > 6) {
    if (!parse_int(t.items[6], s.checksum))
      return fail(at.field_error("checksum", t.items[6], "not an integer"));
    s.has_checksum = true;
  }
  if (t.items.size() > 7 && !parse_int(t.items[7], s.block_size))
    return fail(at.field_error("block size", t.items[7], "not an integer"));
  if (t.items.size() > 8) s.description = std::string(trim(line.substr(t.starts[8])));
  if (s.adc_resolution == 0) s.adc_resolution = default_resolution(s.format);
  if (!has_zero) s.adc_zero = 0;
  if (!has_baseline) s.baseline = s.adc_zero;
  if (!has_init) s.initial_value = s.adc_zero;
  return s;
}

std::string parent_dir(const std::string& path) {
  auto p = std::filesystem::path(path).parent_path();
  return p.empty() ? std::string(".") : p.string();
}

// ---- decoding ----

// Values (counted across the interleaved signals of one file) held by `bytes` bytes of a
// format. A last, partial block holds what WFDB's writers flush into it: one 212 value in two
// bytes, one 310 value per 16-bit word written, one 311 value per byte after the first two.
std::int64_t values_in_bytes(int format, std::int64_t bytes) {
  const Packing p = packing_of(format).value_or(Packing{1, 1});
  const std::int64_t whole = bytes / p.bytes * p.values, rest = bytes % p.bytes;
  if (format == 212 || format == 310) return whole + (rest >= 2 ? 1 : 0);
  if (format == 311) return whole + std::max<std::int64_t>(0, rest - 1);
  return whole;
}

std::int32_t sign_extend(std::uint32_t v, int bits) {
  const std::uint32_t mask = bits == 32 ? ~0u : (1u << bits) - 1, sign = 1u << (bits - 1);
  v &= mask;
  return static_cast<std::int32_t>(v & sign ? v | ~mask : v);
}

}  // namespace

// One signal file and the consecutive header signals stored in it (interleaved).
struct SignalReader::Group {
  std::string path;       // as opened (directory + file name)
  int format = 0;
  Packing packing{2, 1};
  std::size_t first = 0;  // index of its first signal in the header
  std::size_t count = 0;  // number of signals in the file
  std::ifstream in;
  std::vector<std::int32_t> pending;  // values of a packed block decoded ahead of a request
  std::vector<unsigned char> bytes;   // reusable read buffer
  // Format 8: each signal's last value, which the next difference adds to (from the header's
  // initial value), and the signal the next value in the file belongs to.
  std::vector<std::int32_t> running;
  std::size_t next_signal = 0;

  // Decodes the next `want` values; returns how many were available (fewer only at end of file).
  Result<std::size_t> next_values(std::size_t want, std::vector<std::int32_t>& out) {
    out.clear();
    if (format == 0) {  // a null signal: WFDB's no-value at every sample, as long as the others go
      out.assign(want, -32768);
      return want;
    }
    std::size_t take = std::min(want, pending.size());
    out.insert(out.end(), pending.begin(), pending.begin() + take);
    pending.erase(pending.begin(), pending.begin() + take);
    std::size_t rest = want - take;
    if (rest == 0) return want;
    // Packed formats are read in whole blocks; values of the last block beyond the request are
    // kept for the next one.
    const auto per_block = static_cast<std::size_t>(packing.values);
    const std::size_t blocks = (rest + per_block - 1) / per_block;
    bytes.resize(blocks * static_cast<std::size_t>(packing.bytes));
    in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    std::size_t got = static_cast<std::size_t>(in.gcount());
    if (in.bad()) return fail(path + ": read error");
    decode(got, out);
    if (out.size() > want) {
      pending.assign(out.begin() + static_cast<std::ptrdiff_t>(want), out.end());
      out.resize(want);
    }
    return out.size();
  }

  void decode(std::size_t got, std::vector<std::int32_t>& out) {
    const unsigned char* b = bytes.data();
    const auto u16 = [&](std::size_t i) { return static_cast<std::uint32_t>(b[i] | (b[i + 1] << 8)); };
    switch (format) {
      case 8:
        for (std::size_t i = 0; i < got; ++i) {
          std::int32_t& value = running[next_signal];
          value += static_cast<std::int8_t>(b[i]);
          out.push_back(value);
          next_signal = (next_signal + 1) % running.size();
        }
        return;
      case 80:
        for (std::size_t i = 0; i < got; ++i) out.push_back(static_cast<std::int32_t>(b[i]) - 128);
        return;
      case 16:
        for (std::size_t i = 0; i + 1 < got; i += 2) out.push_back(sign_extend(u16(i), 16));
        return;
      case 61:
        for (std::size_t i = 0; i + 1 < got; i += 2) out.push_back(sign_extend(static_cast<std::uint32_t>(b[i] << 8 | b[i + 1]), 16));
        return;
      case 160:
        for (std::size_t i = 0; i + 1 < got; i += 2) out.push_back(static_cast<std::int32_t>(u16(i)) - 32768);
        return;
      case 24:
        for (std::size_t i = 0; i + 2 < got; i += 3) out.push_back(sign_extend(u16(i) | static_cast<std::uint32_t>(b[i + 2]) << 16, 24));
        return;
      case 32:
        for (std::size_t i = 0; i + 3 < got; i += 4) out.push_back(sign_extend(u16(i) | u16(i + 2) << 16, 32));
        return;
      case 310:
        // Words w0, w1: values 0 and 1 in bits 1-10 of each; value 2's low five bits in bits
        // 11-15 of w0, its high five in bits 11-15 of w1.
        for (std::size_t i = 0; i + 1 < got; i += 4) {
          const std::uint32_t w0 = u16(i);
          out.push_back(sign_extend(w0 >> 1, 10));
          if (i + 3 >= got) break;
          const std::uint32_t w1 = u16(i + 2);
          out.push_back(sign_extend(w1 >> 1, 10));
          out.push_back(sign_extend((w0 >> 11) | ((w1 >> 11) << 5), 10));
        }
        return;
      case 311:
        // One little-endian 32-bit word: values in bits 0-9, 10-19 and 20-29.
        for (std::size_t i = 0; i + 1 < got; i += 4) {
          std::uint32_t word = u16(i);
          std::size_t have = 1;
          if (i + 2 < got) word |= static_cast<std::uint32_t>(b[i + 2]) << 16, have = 2;
          if (i + 3 < got) word |= static_cast<std::uint32_t>(b[i + 3]) << 24, have = 3;
          for (std::size_t k = 0; k < have; ++k) out.push_back(sign_extend(word >> (10 * k), 10));
        }
        return;
      default:  // 212
        for (std::size_t i = 0; i + 1 < got; i += 3) {
          const std::uint32_t b1 = b[i + 1];
          out.push_back(sign_extend(b[i] | ((b1 & 0x0Fu) << 8), 12));
          if (i + 2 < got) out.push_back(sign_extend(b[i + 2] | ((b1 & 0xF0u) << 4), 12));
        }
        return;
    }
  }
};

Result<RecordHeader> read_header(const std::string& record_path) {
  const std::string file = record_path + ".hea";
  std::ifstream in(file, std::ios::binary);
  if (!in) return fail(file + ": cannot open header: " + std::strerror(errno));
  RecordHeader h;
  h.directory = parent_dir(file);
  h.path = file;
  bool have_record_line = false;
  int line_no = 0;
  for (std::string raw; std::getline(in, raw);) {
    ++line_no;
    std::string_view line = trim(raw);
    if (line.empty()) continue;
    if (line.front() == '#') {
      h.comments.emplace_back(trim(line.substr(1)));
      continue;
    }
    Where at{file, line_no};
    if (!have_record_line) {
      if (auto r = parse_record_line(line, at, h); !r) return fail(r.error().message);
      have_record_line = true;
    } else if (static_cast<int>(h.signals.size()) < h.signal_count) {
      auto s = parse_signal_line(line, at);
      if (!s) return fail(s.error().message);
      h.signals.push_back(std::move(*s));
    } else if (auto s = parse_signal_line(line, at);
               s && std::any_of(h.signals.begin(), h.signals.end(), [&](const SignalInfo& x) { return x.file == s->file; })) {
      // One more signal of a file the header's signals are in: the record line undercounts the
      // file's interleaved signals, and every frame would be read at the wrong width.
      return fail(file + ":" + std::to_string(line_no) + ": record line announces " + std::to_string(h.signal_count) +
                  " signal" + (h.signal_count == 1 ? "" : "s") + ", but this line is one more signal of " + s->file +
                  " (fix the number of signals on the record line)");
    }
    // Other lines after the last signal line (info strings without '#') are ignored, as WFDB does.
  }
  if (in.bad()) return fail(file + ": read error: " + std::strerror(errno ? errno : EIO));
  if (!have_record_line) return fail(file + ": no record line");
  if (static_cast<int>(h.signals.size()) < h.signal_count)
    return fail(file + ": record line announces " + std::to_string(h.signal_count) +
                " signals, found " + std::to_string(h.signals.size()) + " signal lines");
  return h;
}

SignalReader::SignalReader(SignalReader&&) noexcept = default;
SignalReader& SignalReader::operator=(SignalReader&&) noexcept = default;
SignalReader::~SignalReader() = default;

Result<SignalReader> SignalReader::open(const std::string& record_path) {
  auto h = read_header(record_path);
  if (!h) return fail(h.error().message);
  SignalReader r;
  r.header_ = std::move(*h);
  const auto& sigs = r.header_.signals;
  for (std::size_t i = 0; i < sigs.size();) {
    std::size_t j = i + 1;
    // Null signals (format 0) share no file, whatever their file is called ("~", anywhere).
    while (j < sigs.size() && sigs[j].file == sigs[i].file && (sigs[i].format == 0) == (sigs[j].format == 0)) {
      if (sigs[j].format != sigs[i].format)
        return fail(record_path + ".hea: signals " + std::to_string(i) + " and " +
                    std::to_string(j) + " share file " + sigs[i].file + " but differ in format");
      ++j;
    }
    for (const auto& g : r.groups_)
      if (sigs[i].format != 0 && g->format != 0 && sigs[g->first].file == sigs[i].file)
        return fail(record_path + ".hea: signals of file " + sigs[i].file + " are not consecutive");
    auto g = std::make_unique<Group>();
    g->path = (std::filesystem::path(r.header_.directory) / sigs[i].file).string();
    g->format = sigs[i].format;
    for (std::size_t k = i; k < j; ++k) g->running.push_back(sigs[k].initial_value);
    g->first = i;
    g->count = j - i;
    if (g->format == 0) {  // null signals (file "~" by convention): no file to open
      r.groups_.push_back(std::move(g));
      i = j;
      continue;
    }
    g->packing = *packing_of(g->format);
    std::error_code ec;
    // A device or a pipe has no size to check the header's sample count against (and a pipe
    // with no writer would hold the open below for ever): said before it is opened.
    if (const auto kind = std::filesystem::status(g->path, ec).type(); !ec && kind != std::filesystem::file_type::regular)
      return fail(g->path + ": the signal file is not a regular file (a device, a pipe or a directory): WFDB signals are read from files");
    g->in.open(g->path, std::ios::binary);
    if (!g->in) return fail(g->path + ": cannot open signal file: " + std::strerror(errno));
    auto size = static_cast<std::int64_t>(std::filesystem::file_size(g->path, ec));
    if (ec) return fail(g->path + ": cannot stat signal file: " + ec.message());
    std::int64_t offset = sigs[i].byte_offset;
    if (offset > 0 && offset >= size)
      return fail(record_path + ".hea: signal " + std::to_string(i) + ": its byte offset (+" + std::to_string(offset) + " in " +
                  std::to_string(sigs[i].format) + "+" + std::to_string(offset) + ") is past the end of " + sigs[i].file + " (" +
                  std::to_string(size) + " bytes)");
    std::int64_t found = values_in_bytes(g->format, std::max<std::int64_t>(0, size - offset)) /
                         static_cast<std::int64_t>(g->count);
    std::int64_t expected = r.header_.samples_per_signal;
    if (expected > 0 && found < expected) {
      // A file of exactly the size the other format would take for the header's count was
      // written in that format, not cut short: a header saying 16 over format-212 data.
      std::string hint;
      for (const int other : {212, 16})
        if (other != g->format && (g->format == 212 || g->format == 16) &&
            values_in_bytes(other, std::max<std::int64_t>(0, size - offset)) / static_cast<std::int64_t>(g->count) == expected)
          hint = "; its size is what format " + std::to_string(other) + " takes for that many: is the header's format (" +
                 std::to_string(g->format) + ") that of the file?";
      // A byte offset (`212+64801`) is read past: the bytes said are those after it.
      return fail(g->path + ": truncated: expected " + std::to_string(expected) + " samples per signal, found " +
                  std::to_string(found) + " (" +
                  (offset > 0 ? std::to_string(std::max<std::int64_t>(0, size - offset)) + " bytes after the header's byte offset " +
                                    std::to_string(offset) + ", of " + std::to_string(size)
                              : std::to_string(size) + " bytes") +
                  ")" + hint);
    }
    g->in.seekg(offset);
    r.groups_.push_back(std::move(g));
    i = j;
  }
  return r;
}

Result<std::size_t> SignalReader::read(std::size_t frames,
                                       std::vector<std::vector<std::int32_t>>& out) {
  if (!error_.empty()) return fail(error_);
  const auto nsig = static_cast<std::size_t>(header_.signal_count);
  const std::int64_t total = header_.samples_per_signal;
  if (total > 0) frames = static_cast<std::size_t>(std::min<std::int64_t>(
                     static_cast<std::int64_t>(frames), total - position_));
  if (frames == 0 || nsig == 0) return std::size_t{0};
  // Null signals alone, with no sample count: nothing says where they end.
  if (total <= 0 && std::all_of(groups_.begin(), groups_.end(), [](const auto& g) { return g->format == 0; }))
    return std::size_t{0};
  if (out.size() < nsig) out.resize(nsig);

  // Decode every file first, then append: an error leaves `out` without a partial frame.
  std::vector<std::vector<std::int32_t>> decoded(groups_.size());
  std::size_t whole = frames;
  for (std::size_t k = 0; k < groups_.size(); ++k) {
    Group& g = *groups_[k];
    auto got = g.next_values(frames * g.count, decoded[k]);
    if (!got) return error_ = got.error().message, fail(error_);
    std::size_t f = *got / g.count;
    if (f < frames && total > 0) {
      error_ = g.path + ": truncated: expected " + std::to_string(total) +
               " samples per signal, found " + std::to_string(position_ + static_cast<std::int64_t>(f));
      return fail(error_);
    }
    whole = std::min(whole, f);
  }
  for (std::size_t k = 0; k < groups_.size(); ++k) {
    const Group& g = *groups_[k];
    for (std::size_t c = 0; c < g.count; ++c) {
      auto& dst = out[g.first + c];
      dst.reserve(dst.size() + whole);
      for (std::size_t f = 0; f < whole; ++f) dst.push_back(decoded[k][f * g.count + c]);
    }
  }
  position_ += static_cast<std::int64_t>(whole);
  return whole;
}

Result<Signals> read_signals(const std::string& record_path) {
  auto reader = SignalReader::open(record_path);
  if (!reader) return fail(reader.error().message);
  Signals s;
  s.samples.resize(static_cast<std::size_t>(reader->header().signal_count));
  const std::int64_t total = reader->header().samples_per_signal;
  const std::size_t chunk = total > 0 ? static_cast<std::size_t>(total) : std::size_t{1} << 16;
  for (;;) {
    auto n = reader->read(chunk, s.samples);
    if (!n) return fail(n.error().message);
    if (*n == 0) break;
  }
  s.header = reader->header();
  return s;
}

double to_physical(std::int32_t adu, const SignalInfo& info) {
  double gain = info.gain == 0 ? 200.0 : info.gain;
  return (static_cast<double>(adu) - info.baseline) / gain;
}

namespace {

std::string lower(std::string_view text) {
  std::string out(text);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

// Units of a voltage, as millivolts per unit; 0 for anything else.
double millivolts_per_unit(std::string_view units) {
  const std::string u = lower(units);
  if (u == "mv") return 1;
  if (u == "uv" || u == "\xc2\xb5v" || u == "\xce\xbcv") return 1e-3;  // µ as MICRO SIGN or GREEK MU
  if (u == "v") return 1e3;
  if (u == "nv") return 1e-6;
  return 0;
}

// Whether a signal's description names an ECG lead: "ECG", "EKG", "ECG1", "ECG lead II",
// "Lead II", "MLII", "ML II", "V1".."V6", "I", "II", "III", "aVR", "aVL", "aVF", "D1".."D3", and
// the bipolar chest leads of Holter records ("MCL1", "CM2", "CC5").
bool names_ecg_lead(std::string_view description) {
  std::string d = lower(description);
  std::erase(d, ' ');
  if (d.find("ecg") != std::string::npos || d.find("ekg") != std::string::npos) return true;
  if (d.starts_with("lead")) d.erase(0, 4);
  // "V" alone is the chest lead of a bedside monitor's record (MIMIC: "II", "V", "AVR").
  for (const char* lead : {"mli", "mlii", "mliii", "i", "ii", "iii", "avr", "avl", "avf", "d1", "d2", "d3", "v", "v1", "v2", "v3",
                           "v4", "v5", "v6", "mv1", "mv2", "mv3", "mv4", "mv5", "mv6", "modv1", "modv5"})
    if (d == lead) return true;
  // MCLn, CMn, CCn, MLn (n a chest position 1-6; ML2 and ML5 in Holter records).
  for (const char* chest : {"mcl", "cm", "cc", "ml"})
    if (d.size() == std::strlen(chest) + 1 && d.starts_with(chest) && d.back() >= '1' && d.back() <= '6') return true;
  // Chest leads beyond V6 and the right-sided ones: V7-V9, V1R-V9R. (Frank's X, Y, Z and EASI's
  // ES, AS, AI are left out: an accelerometer's or any device's channels are named so too.)
  if ((d.size() == 2 || (d.size() == 3 && d.back() == 'r')) && d[0] == 'v' && d[1] >= '1' && d[1] <= '9') return true;
  return false;
}

}  // namespace

std::vector<std::string> unread_samples(const RecordHeader& header) {
  std::vector<std::string> out;
  const std::int64_t expected = header.samples_per_signal;
  if (expected <= 0) return out;
  for (std::size_t i = 0; i < header.signals.size();) {
    std::size_t j = i + 1;
    while (j < header.signals.size() && header.signals[j].file == header.signals[i].file &&
           (header.signals[i].format == 0) == (header.signals[j].format == 0))  // as SignalReader::open groups them
      ++j;
    const SignalInfo& first = header.signals[i];
    const std::string path = (std::filesystem::path(header.directory) / first.file).string();
    std::error_code ec;
    const auto size = static_cast<std::int64_t>(std::filesystem::file_size(path, ec));
    if (!ec && packing_of(first.format)) {
      const std::int64_t found = values_in_bytes(first.format, std::max<std::int64_t>(0, size - first.byte_offset)) /
                                 static_cast<std::int64_t>(j - i);
      // Values of a last packed block beyond the count are its padding (212: one; 310, 311: two).
      if (found > expected + (packing_of(first.format)->values - 1))
        out.push_back(path + " holds " + std::to_string(found) + " samples per signal, the header " + header.path + " says " +
                      std::to_string(expected) + ": the last " + std::to_string(found - expected) +
                      " are not read (is the header's sample count right?)");
    }
    i = j;
  }
  return out;
}

std::vector<std::string> checksum_mismatches(const Signals& signals) {
  std::vector<std::uint16_t> sums;
  for (const auto& samples : signals.samples) {
    std::uint16_t sum = 0;
    for (std::int32_t v : samples) sum = static_cast<std::uint16_t>(sum + static_cast<std::uint16_t>(v));
    sums.push_back(sum);
  }
  return checksum_mismatches(signals.header, sums);
}

std::vector<std::string> checksum_mismatches(const RecordHeader& header, const std::vector<std::uint16_t>& sums) {
  std::vector<std::string> out;
  // Without a sample count the header was written before the samples were known (a recorder
  // that did not know how long it would run), and its checksum field with it: often 0, which
  // warned of a file in another format.
  if (header.samples_per_signal == 0) return out;
  // A file holding more samples than the header counts: the sums are of the part read, and
  // "is it in format 212?" sent a researcher after the wrong cause.
  const std::vector<std::string> unread = unread_samples(header);
  for (std::size_t i = 0; i < sums.size() && i < header.signals.size(); ++i) {
    const SignalInfo& info = header.signals[i];
    if (!info.has_checksum) continue;
    const std::uint16_t sum = sums[i];
    const auto said = static_cast<std::uint16_t>(info.checksum);
    const std::string path = (std::filesystem::path(header.directory) / info.file).string();
    const bool cut_short = std::any_of(unread.begin(), unread.end(), [&](const std::string& u) { return u.starts_with(path + " holds "); });
    if (sum != said)
      out.push_back(header.path + ": signal " + std::to_string(i) + " (" +
                    info.description + "): its samples add up to " + std::to_string(static_cast<std::int16_t>(sum)) +
                    ", the header's checksum is " + std::to_string(static_cast<std::int16_t>(said)) +
                    (cut_short ? " (the header's sample count leaves samples of " + info.file + " unread: is it right?)"
                               : " (is " + info.file + " in format " + std::to_string(info.format) + "?)"));
  }
  return out;
}

std::optional<std::string> default_rate_warning(const RecordHeader& header) {
  if (header.fs_given) return std::nullopt;
  return header.path + ": the record line gives no sampling frequency: WFDB's default of 250 Hz is taken (a signal "
                       "sampled at another rate gives heart rates and HRV off by the ratio; give the rate after the "
                       "number of signals)";
}

std::optional<std::string> non_voltage_warning(const RecordHeader& header, std::size_t signal) {
  if (signal >= header.signals.size()) return std::nullopt;
  const SignalInfo& info = header.signals[signal];
  if (millivolts_per_unit(info.units) > 0) return std::nullopt;
  return header.path + ": signal " + std::to_string(signal) + " (" + info.description + "), read as the ECG, is in '" +
         info.units + "', not a voltage: its samples are read as millivolts at the header's gain (is the header right?)";
}

std::int32_t invalid_sample(const SignalInfo& info) {
  switch (info.format) {
    case 80: return -128;
    case 212: return -2048;
    case 310: case 311: return -512;
    case 24: return -(1 << 23);
    case 8: case 32: return std::numeric_limits<std::int32_t>::min();
    default: return -32768;
  }
}

double gain_per_mv(const SignalInfo& info) {
  const double gain = info.gain == 0 ? 200 : info.gain;
  const double mv = millivolts_per_unit(info.units);
  return mv > 0 ? gain / mv : gain;
}

std::size_t ecg_signal(const RecordHeader& header) {
  const auto& sigs = header.signals;
  for (std::size_t i = 0; i < sigs.size(); ++i)
    if (sigs[i].format != 0 && names_ecg_lead(sigs[i].description)) return i;
  for (std::size_t i = 0; i < sigs.size(); ++i)
    if (sigs[i].format != 0 && millivolts_per_unit(sigs[i].units) > 0) return i;
  for (std::size_t i = 0; i < sigs.size(); ++i)
    if (sigs[i].format != 0) return i;
  return 0;
}

std::optional<std::string> not_an_ecg_signal(const RecordHeader& header, std::size_t signal) {
  if (signal >= header.signals.size() || header.signals[signal].format != 0) return std::nullopt;
  return header.path + ": signal " + std::to_string(signal) +
         (header.signals[signal].description.empty() ? "" : " (" + header.signals[signal].description + ")") +
         " is a null signal (format 0: WFDB's place for a signal that was not recorded), which has no samples";
}

}  // namespace tahvel::aggregation
