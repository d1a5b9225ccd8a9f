// Environment sensing on the whiteboard (docs/spatial.md, "Environment"; vocabulary:
// docs/vocabulary.md, "Spatial"): sensing subscriptions, what each mote can sense, readings and
// the per-room environment item, built and read in one place for the mote simulator
// (tahvel-env-motes), the aggregator (tahvel-environment), tests and the demo.
//
//   <sub> a tv:SensingSubscription ; tv:quantity tv:temperature ; tv:area <room> ;
//         tv:maxAgeS 900 ; tv:durationS 3600 ;             # from the item's asserted time
//         tv:thresholdAbove 25 ; tv:thresholdPeriodS 60 .  # optional rule
//   <mote> tv:senses tv:temperature, tv:movement .
//   _:o a sosa:Observation ; sosa:madeBySensor <mote> ; sosa:observedProperty tv:temperature ;
//       sosa:hasSimpleResult 21.4 .                        # asserted at the sensing time
//   <room> tv:environment <room>/environment .
//   <room>/environment a tv:RoomEnvironment ; tv:room <room> ; tv:validTimeS 900 ;
//       tv:computedAt <ns> ; tv:temperature 21.4 ; tv:temperatureAt <ns> ;
//       tv:humidity "unknown" ; tv:light "unknown" ; tv:movementLevel 20 .
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "tahvel/node/node.h"
#include "tahvel/spatial/environment.h"
#include "tahvel/spatial/error.h"

namespace tahvel::spatial {

// tv:<quantity> as an IRI.
std::string quantity_iri(Quantity q);

// The persistent item of a subscription (subject s.iri). With duration_s > 0 it ends duration_s
// after the item's asserted time (`asserted_at_ns`, also written as the item's asserted_at).
node::Item sensing_subscription_item(const SensingSubscription& s, double duration_s,
                                     std::int64_t asserted_at_ns);

struct SensingSubscriptions {
  std::vector<SensingSubscription> subscriptions;  // by IRI order
  std::vector<std::string> problems;               // "<iri>: tv:maxAgeS ..." (skipped ones)
};

// Every tv:SensingSubscription on the board. A subscription without a known tv:quantity, a
// tv:area or a positive tv:maxAgeS is skipped and named in `problems`.
Result<SensingSubscriptions> read_sensing_subscriptions(const node::Snapshot& snapshot);

// What each mote senses (tv:senses), by mote IRI.
Result<std::map<std::string, std::vector<Quantity>>> read_capabilities(const node::Snapshot& snapshot);

// One reading of `mote` (asserted at r.at_ns).
node::Item reading_item(const std::string& mote_iri, const Reading& r);

struct MoteReading {
  std::string mote;
  Reading reading;
  std::uint64_t record = 0;  // the id of its sosa:madeBySensor record: when it was stored
};

// Readings asserted at or after `since_ns`, in record order. Items without a known quantity
// or a numeric result are skipped.
Result<std::vector<MoteReading>> readings_since(const node::Snapshot& snapshot, std::int64_t since_ns);

// The environment item of `room` (subject <room>/environment, plus <room> tv:environment it).
node::Item environment_item(const std::string& room_iri, const RoomEnvironment& env,
                            std::int64_t now_ns, double valid_s);
std::string environment_iri(const std::string& room_iri);

}  // namespace tahvel::spatial
