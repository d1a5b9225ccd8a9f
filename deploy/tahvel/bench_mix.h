// The record mix that every system in `tahvel bench store` writes and queries: sensor
// observations like those of the HRV pipeline, generated deterministically (fixed seed, no
// <random> distributions, so every platform and every run sees the same records).
//
// Observation k is one 10-triple item with subject <http://example.org/home1/obs/k>: its type,
// sensor, observed property, feature of interest, result (integer or decimal), result time
// (xsd:dateTime), the observation it was derived from, the agent it is attributed to, a
// sequence number and one of a unit IRI, a short label or a quality string: 12 predicates in all.
// Observation k is asserted at observation_time(k), a millisecond after observation k - 1.
// Triple i of the whole stream is triple i % 10 of observation i / 10.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "tahvel/node/term.h"

namespace tahvel::cli::bench {

inline constexpr std::size_t kTriplesPerObservation = 10;
inline constexpr const char* kNodeIri = "http://example.org/home1";

// The subject IRI of observation k.
std::string observation_iri(std::uint64_t k);

// When observation k held (Item::asserted_at), ns since the epoch: 2026-11-18T00:00:00Z + k ms.
inline constexpr std::int64_t observation_time(std::uint64_t k) {
  return 1'795'046'400'000'000'000 + static_cast<std::int64_t>(k) * 1'000'000;
}

// Observation k as one item of kTriplesPerObservation triples.
node::Item observation(std::uint64_t k);

// Observations [first, first + count), one item each.
std::vector<node::Item> observations(std::uint64_t first, std::size_t count);

// Triples [first, first + count) of the stream, one single-triple item each.
std::vector<node::Item> single_triples(std::uint64_t first, std::size_t count);

// Every predicate IRI the mix uses.
const std::vector<std::string>& mix_predicates();

// A small deterministic generator (splitmix64) for the query workloads.
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next();
  std::uint64_t below(std::uint64_t n) { return n == 0 ? 0 : next() % n; }

 private:
  std::uint64_t state_;
};

}  // namespace tahvel::cli::bench
