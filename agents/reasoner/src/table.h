// Open-addressing hash tables for the evaluator: millions of small entries, no per-entry
// allocation (std::unordered_map costs ~40 bytes and an allocation per entry). Private.
#pragma once

#include <cstdint>
#include <vector>

namespace tahvel::reasoner {

inline constexpr std::uint32_t kNone = 0xffffffffu;

inline std::uint64_t mix64(std::uint64_t x) {  // splitmix64 finaliser
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

// A set of u32 values (row or term ids) found by a caller-computed hash and equality; each
// slot keeps 32 bits of the hash so that growing never calls back into the caller.
class IdTable {
 public:
  template <class Eq>
  std::uint32_t find(std::uint64_t hash, Eq&& eq) const {
    if (slots_.empty()) return kNone;
    const std::uint32_t h = static_cast<std::uint32_t>(hash >> 32);
    for (std::size_t i = h & mask_;; i = (i + 1) & mask_) {
      const std::uint64_t s = slots_[i];
      if (s == kEmpty) return kNone;
      if (static_cast<std::uint32_t>(s >> 32) == h && eq(static_cast<std::uint32_t>(s))) return static_cast<std::uint32_t>(s);
    }
  }
  // Precondition: not present.
  void insert(std::uint64_t hash, std::uint32_t value) {
    if ((count_ + 1) * 4 > slots_.size() * 3) grow();
    place(static_cast<std::uint32_t>(hash >> 32), value);
    ++count_;
  }
  void clear() { slots_.clear(); count_ = 0; mask_ = 0; }

 private:
  static constexpr std::uint64_t kEmpty = ~0ull;
  void place(std::uint32_t h, std::uint32_t value) {
    std::size_t i = h & mask_;
    while (slots_[i] != kEmpty) i = (i + 1) & mask_;
    slots_[i] = (static_cast<std::uint64_t>(h) << 32) | value;
  }
  void grow() {
    std::vector<std::uint64_t> old = std::move(slots_);
    slots_.assign(old.empty() ? 16 : old.size() * 2, kEmpty);
    mask_ = slots_.size() - 1;
    for (std::uint64_t s : old) if (s != kEmpty) place(static_cast<std::uint32_t>(s >> 32), static_cast<std::uint32_t>(s));
  }
  std::vector<std::uint64_t> slots_;
  std::size_t count_ = 0, mask_ = 0;
};

// u64 key (never ~0) to u32 value.
class KeyMap {
 public:
  std::uint32_t get(std::uint64_t key) const {
    if (keys_.empty()) return kNone;
    for (std::size_t i = mix64(key) & mask_;; i = (i + 1) & mask_) {
      if (keys_[i] == key) return values_[i];
      if (keys_[i] == kEmpty) return kNone;
    }
  }
  // Sets key to value; returns the previous value or kNone.
  std::uint32_t put(std::uint64_t key, std::uint32_t value) {
    if ((count_ + 1) * 4 > keys_.size() * 3) grow();
    for (std::size_t i = mix64(key) & mask_;; i = (i + 1) & mask_) {
      if (keys_[i] == key) { std::uint32_t old = values_[i]; values_[i] = value; return old; }
      if (keys_[i] == kEmpty) { keys_[i] = key; values_[i] = value; ++count_; return kNone; }
    }
  }

 private:
  static constexpr std::uint64_t kEmpty = ~0ull;
  void grow() {
    std::vector<std::uint64_t> old_keys = std::move(keys_);
    std::vector<std::uint32_t> old_values = std::move(values_);
    std::size_t n = old_keys.empty() ? 16 : old_keys.size() * 2;
    keys_.assign(n, kEmpty);
    values_.assign(n, kNone);
    mask_ = n - 1;
    count_ = 0;
    for (std::size_t i = 0; i < old_keys.size(); ++i) if (old_keys[i] != kEmpty) put(old_keys[i], old_values[i]);
  }
  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> values_;
  std::size_t count_ = 0, mask_ = 0;
};

}  // namespace tahvel::reasoner
