// Tahvel's side of `tahvel bench store` where it needs more than a loop: creating the stores
// and measuring the latency from Agent::store() in one process to the return of Agent::take()
// in another.
#pragma once

#include <chrono>
#include <cstddef>
#include <filesystem>

#include "bench_measure.h"
#include "tahvel/node/node.h"

namespace tahvel::cli::bench {

// A new store in `dir` (which must not hold one) with node IRI kNodeIri.
node::Result<node::Node> tahvel_init(const std::filesystem::path& dir, node::Durability durability);

// Store-to-wake latency. Creates a store in `dir` and forks a subscriber that opens it after
// the fork (no LMDB handle crosses the fork), subscribes to a probe predicate and loops on
// take(). This process then stores `samples` one-triple probe items, one at a time: each only
// after the subscriber has taken the previous one and `pause` has passed, so that every
// delivery wakes a sleeping subscriber. The send time (taken just before store()) and the
// wake time (taken as take() returns with the item) pass through memory shared with the child.
// The subscriber takes with Ack::manual and acknowledges after noting the time, as an agent
// acknowledges after processing: the wake is the moment it holds the item, not the later
// write that removes it from its input buffer. With no pause the probes run back to back, the
// writer asleep until the subscriber has taken the last one, as a socket ping-pong does.
// `where` pins the writer and the subscriber.
struct WakeFigures {
  Percentiles wake;         // store() called -> take() returned in the subscriber
  Percentiles store_call;   // store() called -> store() returned (commit, routing, futex wake)
  Percentiles after_store;  // store() returned -> take() returned
};
node::Result<WakeFigures> tahvel_wake(const std::filesystem::path& dir, std::size_t samples,
                                      std::chrono::microseconds pause, Placement where = {});

}  // namespace tahvel::cli::bench
