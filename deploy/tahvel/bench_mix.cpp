// Deterministic sensor-observation records for `tahvel bench store` (see bench_mix.h).
// Each observation is derived from its own index only, so any slice of the stream can be
// generated on its own, outside the timed sections, in the same way for every system.
#include "bench_mix.h"

#include <cstdio>

namespace tahvel::cli::bench {
namespace {

using node::Term;

const std::string kSosa = "http://www.w3.org/ns/sosa/";
const std::string kProv = "http://www.w3.org/ns/prov#";
const std::string kRdfs = "http://www.w3.org/2000/01/rdf-schema#";
const std::string kQudt = "http://qudt.org/schema/qudt/";
const std::string kUnit = "http://qudt.org/vocab/unit/";
const std::string kEx = "http://example.org/vocab#";
const std::string kRdfType = std::string(node::kRdfType);

struct Property {
  const char* name;
  const char* unit;
  bool integer;
  std::int64_t base, spread;  // value = base + rng % spread (decimals: in hundredths)
};

const Property kProperties[] = {
    {"HeartRate", "BEAT-PER-MIN", true, 55, 40}, {"RRInterval", "MilliSEC", true, 600, 500},
    {"RMSSD", "MilliSEC", false, 1500, 6000},    {"SDNN", "MilliSEC", false, 2000, 8000},
    {"Temperature", "DEG_C", false, 1800, 800},  {"Humidity", "PERCENT", false, 3000, 4000},
};
const char* kSensors[] = {"ecg1",         "ecg2",         "rr1",      "hrv",
                          "temp-kitchen", "temp-bedroom", "hum-bath", "hum-bedroom"};
const char* kLabels[] = {"window 30 s", "resting", "night", "walking", "after meal"};
const char* kQuality[] = {"ok", "ok", "ok", "artefact", "ectopic", "noisy"};

std::uint64_t mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

std::string home(const std::string& path) { return std::string(kNodeIri) + "/" + path; }

std::string decimal(std::int64_t hundredths) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%lld.%02lld", static_cast<long long>(hundredths / 100),
                static_cast<long long>(hundredths % 100));
  return buf;
}

// 2024-03-01T00:00:00Z plus k seconds (+ a few ms of jitter), as xsd:dateTime.
std::string date_time(std::uint64_t k, std::uint64_t jitter_ms) {
  std::uint64_t s = k, days = s / 86400;
  s %= 86400;
  unsigned day = 1 + static_cast<unsigned>(days % 28),
           month = 3 + static_cast<unsigned>(days / 28 % 9);
  char buf[40];
  std::snprintf(buf, sizeof buf, "2024-%02u-%02uT%02u:%02u:%02u.%03uZ", month, day,
                static_cast<unsigned>(s / 3600), static_cast<unsigned>(s / 60 % 60),
                static_cast<unsigned>(s % 60), static_cast<unsigned>(jitter_ms % 1000));
  return buf;
}

Term result(const Property& prop, std::uint64_t r) {
  std::int64_t v =
      prop.base + static_cast<std::int64_t>(r % static_cast<std::uint64_t>(prop.spread));
  if (prop.integer) return Term::integer(v);
  return Term::literal(decimal(v), std::string(node::xsd::kDecimal));
}

// The tenth triple: a unit IRI, a short label or a quality string.
void add_extra(node::Item& item, const Term& obs, const Property& prop, std::uint64_t r) {
  switch (r % 3) {
    case 0:
      item.add(obs, Term::iri(kQudt + "unit"), Term::iri(kUnit + prop.unit));
      break;
    case 1:
      item.add(obs, Term::iri(kRdfs + "label"), Term::literal(kLabels[r / 3 % 5]));
      break;
    default:
      item.add(obs, Term::iri(kEx + "quality"), Term::literal(kQuality[r / 3 % 6]));
      break;
  }
}

}  // namespace

std::uint64_t Rng::next() { return mix(state_++); }

std::string observation_iri(std::uint64_t k) { return home("obs/" + std::to_string(k)); }

node::Item observation(std::uint64_t k) {
  const std::uint64_t r = mix(k ^ 0x7461687665ull);  // fixed seed: "tahve"
  const Property& prop = kProperties[r % 6];
  const Term obs = Term::iri(observation_iri(k));
  node::Item item;
  item.asserted_at = observation_time(k);
  item.triples.reserve(kTriplesPerObservation);
  item.add(obs, Term::iri(kRdfType), Term::iri(kSosa + "Observation"))
      .add(obs, Term::iri(kSosa + "madeBySensor"), Term::iri(home("sensor/") + kSensors[r / 7 % 8]))
      .add(obs, Term::iri(kSosa + "observedProperty"), Term::iri(kEx + prop.name))
      .add(obs, Term::iri(kSosa + "hasFeatureOfInterest"),
           Term::iri(home("person/p") + std::to_string(r / 61 % 3)))
      .add(obs, Term::iri(kSosa + "hasSimpleResult"), result(prop, r >> 20))
      .add(obs, Term::iri(kSosa + "resultTime"),
           Term::literal(date_time(k, r >> 40), std::string(node::xsd::kDateTime)))
      .add(obs, Term::iri(kProv + "wasDerivedFrom"),
           Term::iri(observation_iri(k >= 8 ? k - 1 - (r >> 50) % 8 : 0)))
      .add(obs, Term::iri(kProv + "wasAttributedTo"), Term::iri(home(r % 5 < 3 ? "hrv" : "env")))
      .add(obs, Term::iri(kEx + "sequence"), Term::integer(static_cast<std::int64_t>(k)));
  add_extra(item, obs, prop, r >> 30);
  return item;
}

std::vector<node::Item> observations(std::uint64_t first, std::size_t count) {
  std::vector<node::Item> items;
  items.reserve(count);
  for (std::size_t i = 0; i < count; ++i) items.push_back(observation(first + i));
  return items;
}

std::vector<node::Item> single_triples(std::uint64_t first, std::size_t count) {
  std::vector<node::Item> items;
  items.reserve(count);
  node::Item obs;
  std::uint64_t obs_k = ~0ull;
  for (std::uint64_t i = first; i < first + count; ++i) {
    if (i / kTriplesPerObservation != obs_k) {
      obs_k = i / kTriplesPerObservation;
      obs = observation(obs_k);
    }
    node::Item one;
    one.triples.push_back(obs.triples[i % kTriplesPerObservation]);
    items.push_back(std::move(one));
  }
  return items;
}

const std::vector<std::string>& mix_predicates() {
  static const std::vector<std::string> predicates = {
      kRdfType,
      kSosa + "madeBySensor",
      kSosa + "observedProperty",
      kSosa + "hasFeatureOfInterest",
      kSosa + "hasSimpleResult",
      kSosa + "resultTime",
      kProv + "wasDerivedFrom",
      kProv + "wasAttributedTo",
      kEx + "sequence",
      kQudt + "unit",
      kRdfs + "label",
      kEx + "quality",
  };
  return predicates;
}

}  // namespace tahvel::cli::bench
