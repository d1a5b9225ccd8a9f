// Raw latency floors of the wire libraries: what LCM and Cyclone DDS themselves cost for one
// small message, measured with the libraries alone (no Transport, no link), so that the link's
// latency can be reported as a ratio against them in the same run (tests/bench); and the same
// through the project's own bindings (binding_*), without a link or a store.
//
// raw_*_pingpong measure ping-pong between two threads of this process, each with its own LCM
// instance (two sockets, through the kernel's multicast loopback) or its own DDS participant
// (one Cyclone domain per process: the two participants talk through Cyclone's in-process
// delivery, not the network). The halves (*_echo, *_ping) measure it between two processes,
// as a link's two ends are deployed; for DDS that is the network path (about 30 us one-way on
// the development VM against 8-20 us in-process). One-way latency is half a round trip, and
// each leg of it apart (LatencyFloor::legs_us).
// Packets: run inside a network namespace (tests/tools/netns-run) like everything else that
// sends.
#pragma once

#include <chrono>
#include <functional>
#include <string>
#include <vector>

#include "tahvel/federation/transport.h"

namespace tahvel::federation {

struct LatencyFloor {
  double p50_us = 0;  // median one-way latency (half a round trip), microseconds
  double p99_us = 0;  // 99th percentile of the same
  int rounds = 0;     // round trips measured (after warm-up; lost ones are not counted)
  std::vector<double> one_way_us;  // every sample, ascending (to pool several measurements)
  // The two legs of each round apart, split where the echo took the ping (its clock is this
  // one: CLOCK_MONOTONIC of the same machine): ping to taken, and taken to the pong taken back
  // (the echo's turn-around included), so that each round's legs add up to its round trip.
  // Half a round trip averages a slow leg with a fast one; a one-way latency measured with one
  // clock (a link's, store to visible) is a single leg, and its tail is the legs' tail. Empty
  // when the echo's stamps do not fall within the rounds (another machine's clock), and for
  // the bindings' floor.
  double leg_p50_us = 0, leg_p99_us = 0;
  std::vector<double> legs_us;  // ascending
};

// `rounds` ping-pongs of a tahvel_ping_t (two int64s: a sequence number, the echo's stamp) over LCM at settings.url, after a warm-up
// of rounds/10 (at least 10). A ping or pong lost by LCM (no answer within 1 s) is retried; more
// than rounds/10 + 10 losses fail with Errc::timeout. rounds must be > 0.
Result<LatencyFloor> raw_lcm_pingpong(const LcmSettings& settings, int rounds);

// The same with a tahvel::Ping (the same two int64s) written and taken on two RELIABLE/KEEP_ALL topics of
// settings.domain (configured with settings.config as open_dds would). Fails with Errc::timeout
// if the two participants do not match within 5 s or an answer takes more than 5 s.
Result<LatencyFloor> raw_dds_pingpong(const DdsSettings& settings, int rounds);

// The two halves of the same ping-pongs, for two processes. `name` names the channels or
// topics; both sides use the same one (unique on the bus). The echo calls `ready` once it
// listens (start pinging after it: LCM has no discovery), answers until the ping side's stop
// message or `idle` without a ping, then returns. The ping side measures `rounds` as above and
// sends the stop message. A DDS echo waits up to 10 s for the ping side to match. `name`: letters,
// digits and underscores only (it goes into DDS topic names).
Result<void> lcm_echo(const LcmSettings& settings, const std::string& name, const std::function<void()>& ready,
                      std::chrono::milliseconds idle);
Result<LatencyFloor> lcm_ping(const LcmSettings& settings, const std::string& name, int rounds);
Result<void> dds_echo(const DdsSettings& settings, const std::string& name, const std::function<void()>& ready,
                      std::chrono::milliseconds idle);
Result<LatencyFloor> dds_ping(const DdsSettings& settings, const std::string& name, int rounds);

// The same ping-pong through this project's bindings (transport.h) instead of the bare library:
// frames of `body_bytes` between two endpoints, as a link sends them but without a store on
// either side. A link's latency then splits into the wire library (the raw floor), what the
// binding adds (this against that) and what the link and the stores add (the link against this).
// binding_echo sends every frame it receives back to its sender until a frame of kind `error`
// arrives or `idle` passes without a frame. binding_ping sends `rounds` frames to `echo_iri`
// (after a warm-up of rounds/10, at least 10), each once the one before came back, then the
// error frame that stops the echo. A frame not back within 1 s is counted lost and the next one
// sent (LCM may drop, and it has no discovery: the first frames may find no echo yet); more than
// rounds/10 + 10 losses fail with Errc::timeout.
Result<void> binding_echo(Transport& endpoint, std::chrono::milliseconds idle);
Result<LatencyFloor> binding_ping(Transport& endpoint, const std::string& echo_iri, int rounds,
                                  std::size_t body_bytes);

}  // namespace tahvel::federation
