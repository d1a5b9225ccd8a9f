// Byte-level encodings shared by the store's tables: LEB128 varints, zigzag for signed values,
// a stable 64-bit hash for the term dictionary. Little code, on every hot path: header-only.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

namespace tahvel::node::codec {

inline void put_varint(std::string& out, std::uint64_t v) {
  while (v >= 0x80) {
    out.push_back(static_cast<char>((v & 0x7f) | 0x80));
    v >>= 7;
  }
  out.push_back(static_cast<char>(v));
}

// Reads a varint at `pos`, advancing it. Returns false on truncated input (corrupt record).
inline bool get_varint(std::string_view in, std::size_t& pos, std::uint64_t& v) {
  v = 0;
  for (int shift = 0; shift < 64 && pos < in.size(); shift += 7) {
    auto byte = static_cast<std::uint8_t>(in[pos++]);
    v |= std::uint64_t(byte & 0x7f) << shift;
    if (!(byte & 0x80)) return true;
  }
  return false;
}

inline std::uint64_t zigzag(std::int64_t v) {
  return (static_cast<std::uint64_t>(v) << 1) ^ static_cast<std::uint64_t>(v >> 63);
}
inline std::int64_t unzigzag(std::uint64_t v) {
  return static_cast<std::int64_t>(v >> 1) ^ -static_cast<std::int64_t>(v & 1);
}

// FNV-1a, 64 bit: stable across processes, versions and platforms (std::hash is not), which
// the on-disk dictionary index needs. Terms are short; ECG chunks hash in ~1 µs per KiB.
inline std::uint64_t hash64(std::string_view bytes) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (unsigned char c : bytes) {
    h ^= c;
    h *= 0x100000001b3ull;
  }
  return h;
}

}  // namespace tahvel::node::codec
