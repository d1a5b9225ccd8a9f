// Environment items on the whiteboard (environment_board.h). Reading is by predicate index:
// subscriptions by rdf:type, readings by sosa:madeBySensor with asserted_at >= since.
#include "tahvel/spatial/environment_board.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <cstdio>

#include "tahvel/spatial/board.h"

namespace tahvel::spatial {

namespace {

const std::string kTv = "https://w3id.org/tahvel#";
const std::string kSosa = "http://www.w3.org/ns/sosa/";

node::Term tv(const char* local) { return node::Term::iri(kTv + local); }
node::Term sosa(const char* local) { return node::Term::iri(kSosa + local); }

node::Term decimal(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.6g", v);
  std::string text = buffer;
  if (text.find_first_of(".eEn") == std::string::npos) text += ".0";
  // %g may print an exponent: xsd:decimal has none, so such values are written as doubles.
  bool exponent = text.find_first_of("eE") != std::string::npos;
  return node::Term::literal(text, std::string(exponent ? node::xsd::kDouble : node::xsd::kDecimal));
}

std::optional<double> number(const node::Term& t) {
  if (!t.is_literal()) return std::nullopt;
  double v = 0;
  const char* begin = t.value.data();
  const char* end = begin + t.value.size();
  if (begin != end && *begin == '+') ++begin;
  auto [ptr, ec] = std::from_chars(begin, end, v);
  if (ec != std::errc() || ptr != end || begin == end) return std::nullopt;
  return v;
}

std::optional<Quantity> quantity_of(const node::Term& t) {
  if (!t.is_iri() || t.value.rfind(kTv, 0) != 0) return std::nullopt;
  return quantity_from_name(std::string_view(t.value).substr(kTv.size()));
}

Unexpected<Error> store_error(const node::Error& e) { return fail(e.message); }

}  // namespace

std::string quantity_iri(Quantity q) { return kTv + quantity_name(q); }
std::string environment_iri(const std::string& room_iri) { return room_iri + "/environment"; }

node::Item sensing_subscription_item(const SensingSubscription& s, double duration_s,
                                     std::int64_t asserted_at_ns) {
  node::Item item;
  item.persistent = true;
  item.asserted_at = asserted_at_ns;
  node::Term self = node::Term::iri(s.iri);
  item.add(self, node::Term::iri(std::string(node::kRdfType)), tv("SensingSubscription"))
      .add(self, tv("quantity"), node::Term::iri(quantity_iri(s.quantity)))
      .add(self, tv("area"), node::Term::iri(s.area))
      .add(self, tv("maxAgeS"), decimal(s.max_age_s));
  if (duration_s > 0) item.add(self, tv("durationS"), decimal(duration_s));
  if (s.rule) {
    item.add(self, tv("thresholdAbove"), decimal(s.rule->above))
        .add(self, tv("thresholdPeriodS"), decimal(s.rule->period_s));
  }
  return item;
}

Result<SensingSubscriptions> read_sensing_subscriptions(const node::Snapshot& snapshot) {
  node::Pattern typed;
  typed.p = node::Term::iri(std::string(node::kRdfType));
  typed.o = tv("SensingSubscription");
  auto heads = snapshot.list(typed);
  if (!heads) return store_error(heads.error());
  SensingSubscriptions out;
  for (const node::Record& head : *heads) {
    if (!head.triple.s.is_iri()) continue;
    node::Pattern about;
    about.s = head.triple.s;
    auto records = snapshot.list(about);
    if (!records) return store_error(records.error());
    SensingSubscription s;
    s.iri = head.triple.s.value;
    std::optional<Quantity> quantity;
    std::optional<double> max_age, duration, above, period;
    std::optional<std::string> area_not_iri;  // a WKT or a name where the room's IRI belongs
    for (const node::Record& r : *records) {
      const std::string& p = r.triple.p.value;
      if (p == kTv + "quantity") quantity = quantity_of(r.triple.o);
      if (p == kTv + "area" && r.triple.o.is_iri()) s.area = r.triple.o.value;
      if (p == kTv + "area" && !r.triple.o.is_iri()) area_not_iri = r.triple.o.value;
      if (p == kTv + "maxAgeS") max_age = number(r.triple.o);
      if (p == kTv + "durationS") duration = number(r.triple.o);
      if (p == kTv + "thresholdAbove") above = number(r.triple.o);
      if (p == kTv + "thresholdPeriodS") period = number(r.triple.o);
    }
    std::string problem;
    if (!quantity) problem = "no tv:quantity among " + std::string("temperature humidity light movement");
    else if (s.area.empty() && area_not_iri)
      problem = "tv:area \"" + *area_not_iri + "\" is a literal: a sensing subscription names a room by its IRI";
    else if (s.area.empty()) problem = "no tv:area (a room IRI)";
    else if (!max_age || !(*max_age > 0) || std::isinf(*max_age))
      problem = "tv:maxAgeS must be a positive finite number of seconds";
    else if (duration && (std::isnan(*duration) || *duration < 0))
      problem = "tv:durationS must be a positive number of seconds (absent: no end)";
    else if (above.has_value() != period.has_value() || (period && !(*period > 0)) || (above && std::isnan(*above)))
      problem = "a threshold rule needs a number tv:thresholdAbove and a positive tv:thresholdPeriodS";
    if (!problem.empty()) {
      out.problems.push_back(s.iri + ": " + problem);
      continue;
    }
    s.quantity = *quantity;
    s.max_age_s = *max_age;
    if (duration && *duration > 0) {
      const std::int64_t length = saturating_ns(*duration);
      s.until_ns = length > std::numeric_limits<std::int64_t>::max() - head.meta.asserted_at
                       ? std::numeric_limits<std::int64_t>::max()
                       : head.meta.asserted_at + length;
    }
    if (above) s.rule = ThresholdRule{*above, *period};
    out.subscriptions.push_back(std::move(s));
  }
  return out;
}

Result<std::map<std::string, std::vector<Quantity>>> read_capabilities(const node::Snapshot& snapshot) {
  node::Pattern senses;
  senses.p = tv("senses");
  std::map<std::string, std::vector<Quantity>> out;
  auto read = snapshot.for_each(senses, [&](const node::Record& r) {
    auto q = quantity_of(r.triple.o);
    if (r.triple.s.is_iri() && q) {
      auto& list = out[r.triple.s.value];
      if (std::find(list.begin(), list.end(), *q) == list.end()) list.push_back(*q);
    }
    return true;
  });
  if (!read) return store_error(read.error());
  return out;
}

node::Item reading_item(const std::string& mote_iri, const Reading& r) {
  node::Item item;
  item.asserted_at = r.at_ns;
  node::Term o = node::Term::blank("o");
  item.add(o, node::Term::iri(std::string(node::kRdfType)), sosa("Observation"))
      .add(o, sosa("madeBySensor"), node::Term::iri(mote_iri))
      .add(o, sosa("observedProperty"), node::Term::iri(quantity_iri(r.quantity)))
      .add(o, sosa("hasSimpleResult"), decimal(r.value));
  return item;
}

Result<std::vector<MoteReading>> readings_since(const node::Snapshot& snapshot, std::int64_t since_ns) {
  node::Pattern made;
  made.p = sosa("madeBySensor");
  made.since = since_ns;
  std::vector<node::Record> heads;
  auto read = snapshot.for_each(made, [&](const node::Record& r) {
    heads.push_back(r);
    return true;
  });
  if (!read) return store_error(read.error());
  std::vector<MoteReading> out;
  for (const node::Record& head : heads) {
    if (!head.triple.o.is_iri()) continue;
    node::Pattern about;
    about.s = head.triple.s;
    auto records = snapshot.list(about);
    if (!records) return store_error(records.error());
    std::optional<Quantity> quantity;
    std::optional<double> value;
    for (const node::Record& r : *records) {
      if (r.triple.p.value == kSosa + "observedProperty") quantity = quantity_of(r.triple.o);
      if (r.triple.p.value == kSosa + "hasSimpleResult") value = number(r.triple.o);
    }
    if (!quantity || !value) continue;
    out.push_back({head.triple.o.value, Reading{*quantity, *value, head.meta.asserted_at}, head.meta.id});
  }
  return out;
}

node::Item environment_item(const std::string& room_iri, const RoomEnvironment& env,
                            std::int64_t now_ns, double valid_s) {
  node::Item item;
  item.asserted_at = now_ns;
  node::Term self = node::Term::iri(environment_iri(room_iri));
  node::Term unknown = node::Term::literal("unknown");
  item.add(node::Term::iri(room_iri), tv("environment"), self)
      .add(self, node::Term::iri(std::string(node::kRdfType)), tv("RoomEnvironment"))
      .add(self, tv("room"), node::Term::iri(room_iri))
      .add(self, tv("validTimeS"), decimal(valid_s))
      .add(self, tv("computedAt"), node::Term::integer(now_ns));
  for (const auto& [q, state] : env.latest) {
    std::string name = quantity_name(q);
    item.add(self, node::Term::iri(kTv + name), state.value ? decimal(*state.value) : unknown);
    if (state.value) item.add(self, node::Term::iri(kTv + name + "At"), node::Term::integer(state.at_ns));
  }
  item.add(self, tv("movementLevel"), env.movement_level ? decimal(*env.movement_level) : unknown);
  return item;
}

}  // namespace tahvel::spatial
