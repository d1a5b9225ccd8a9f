// example_agent_cpp.cpp - a worked Tahvel agent in C++, over the C++ API (tahvel/node/node.h).
// The same agent as example_agent.c; docs/api.md walks through this file.
//
//   usage: example_agent_cpp DIR [--count N] [--idle SECONDS]
//
// Opens the node store in DIR as agent "example-cpp", subscribes to heart-rate observations
//     <obs> tv:heartRate "72"^^xsd:integer .          (any numeric literal; <obs> an IRI)
// and writes one derived item per observation:
//     _:c a tv:HeartRateClassification ;
//         tv:heartRateClass "normal" ;                 "low" < 50 <= "normal" <= 100 < "high"
//         prov:wasDerivedFrom <obs> .                  (left out when <obs> is a blank node:
//                                                       blank nodes are local to their item)
// The subscription is persistent (triples on the whiteboard), and subscribe() returns the one an
// earlier run wrote instead of adding another. Each item is acknowledged only after its derived item is
// stored (Ack::manual), so a crash in between delivers it again on restart.
//
// Stops after N items, after SECONDS without input (default 10), or on SIGINT/SIGTERM.
// Exit status: 0 done, 143 when a process other than its parent sent the SIGTERM (an operator's
// `kill PID`: its supervisor then starts it again, tahvel/node/stop_signal.h), 1 Tahvel error,
// 2 usage.
#include <chrono>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <optional>
#include <string>
#include <string_view>

#include "tahvel/node/node.h"
#include "tahvel/node/stop_signal.h"
#include "tahvel/uri/iri.h"

namespace {

namespace tn = tahvel::node;
using namespace std::chrono_literals;

const std::string kTv(tahvel::uri::kTahvelNs);
const std::string kProv = "http://www.w3.org/ns/prov#";

struct Options {
  std::string dir;
  long count = 0;  // 0: no limit
  long idle_seconds = 10;
};

// The options, or nullopt with `error` saying which argument is wrong.
std::optional<Options> parse_options(int argc, char** argv, std::string& error) {
  Options options;
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    error = "bad argument '" + std::string(arg) + "'";
    if ((arg == "--count" || arg == "--idle") && i + 1 < argc) {
      char* end = nullptr;
      const long value = std::strtol(argv[++i], &end, 10);
      if (*argv[i] == '\0' || *end != '\0' || value < 0) return std::nullopt;
      (arg == "--count" ? options.count : options.idle_seconds) = value;
    } else if (!arg.starts_with("-") && options.dir.empty()) {
      options.dir = arg;
    } else {
      return std::nullopt;
    }
  }
  error = "the node directory is missing";
  if (options.dir.empty()) return std::nullopt;
  return options;
}

int report(std::string_view call, const tn::Error& error) {
  std::cerr << "example_agent_cpp: " << call << " failed: " << tn::errc_name(error.code) << " ("
            << error.message << ")\n";
  return 1;
}

const char* classify(double bpm) {
  if (bpm < 50) return "low";
  if (bpm > 100) return "high";
  return "normal";
}

// The heart rate a literal holds: its whole lexical form a finite decimal number of beats per
// minute ("abc", "NaN", "0x40" and " 72" are none: strtod would skip the space).
std::optional<double> heart_rate(const std::string& text) {
  if (text.empty() || std::isspace(static_cast<unsigned char>(text[0]))) return std::nullopt;
  char* end = nullptr;
  const double bpm = std::strtod(text.c_str(), &end);
  if (end != text.c_str() + text.size() || !std::isfinite(bpm) || bpm < 0 ||
      text.find_first_of("xX") != std::string::npos)
    return std::nullopt;
  return bpm;
}

// The derived item for one heart-rate record; nothing for a literal that is no heart rate
// (logged and skipped, as the pipeline's agents do with malformed input).
std::optional<tn::Item> derive(const tn::Record& observation) {
  const std::optional<double> rate = heart_rate(observation.triple.o.value);
  if (!rate) {
    std::cerr << "example_agent_cpp: " << observation.triple.s.to_ntriples() << " " << observation.triple.o.to_ntriples()
              << ": not a heart rate, skipped\n";
    return std::nullopt;
  }
  const double bpm = *rate;
  const auto c = tn::Term::blank("c");
  tn::Item item;
  item.add(c, tn::Term::iri(std::string(tn::kRdfType)),
           tn::Term::iri(kTv + "HeartRateClassification"))
      .add(c, tn::Term::iri(kTv + "heartRateClass"), tn::Term::literal(classify(bpm)));
  if (observation.triple.s.is_iri())
    item.add(c, tn::Term::iri(kProv + "wasDerivedFrom"), observation.triple.s);
  std::cout << "example_agent_cpp: " << observation.triple.s.to_ntriples() << ' '
            << observation.triple.o.value << " bpm -> " << classify(bpm) << '\n';
  return item;
}

// Derives from every heart-rate record of one delivered item.
tn::Result<void> process(tn::Agent& agent, const tn::Delivery& delivery) {
  for (const tn::Record& record : delivery.records) {
    if (record.triple.p.value != kTv + "heartRate" || !record.triple.o.is_literal()) continue;
    const std::optional<tn::Item> derived = derive(record);
    if (!derived) continue;
    auto stored = agent.store(*derived);
    if (!stored) return tahvel::unexpected(stored.error());
  }
  return {};
}

int run(tn::Agent& agent, const Options& options) {
  long done = 0;
  // Measured, not counted in timeouts: a signal ends a wait early as a timeout does.
  auto last_input = std::chrono::steady_clock::now();
  while (!tn::stop_signal_received() && (options.count == 0 || done < options.count)) {
    auto taken = agent.take(1000ms, tn::Ack::manual);
    if (!taken) return report("take", taken.error());
    if (!*taken) {  // timeout (or a signal): look again
      if (std::chrono::steady_clock::now() - last_input >= std::chrono::seconds(options.idle_seconds)) {
        std::cerr << "example_agent_cpp: no input for " << options.idle_seconds << " s, stopping\n";
        break;
      }
      continue;
    }
    last_input = std::chrono::steady_clock::now();
    const tn::Delivery& delivery = **taken;
    if (auto processed = process(agent, delivery); !processed)
      return report("store", processed.error());  // not acknowledged: delivered again
    if (auto acked = agent.ack(delivery.item); !acked)  // only now
      return report("ack", acked.error());
    ++done;
  }
  std::cerr << "example_agent_cpp: processed " << done << " item(s)\n";
  return tn::stop_exit_status();
}

}  // namespace

int main(int argc, char** argv) {
  std::string error;
  const auto options = parse_options(argc, argv, error);
  if (!options) {
    // The cause last: a supervisor shows the last line of a failed program's log.
    std::cerr << "usage: example_agent_cpp DIR [--count N] [--idle SECONDS]\n"
              << "example_agent_cpp: " << error << "\n";
    return 2;
  }
  tn::install_stop_signal_handlers();

  auto node = tn::Node::open(options->dir);
  if (!node) return report("open " + options->dir, node.error());
  auto agent = node->agent("example-cpp");
  if (!agent) return report("agent", agent.error());
  std::cerr << "example_agent_cpp: running as " << agent->iri() << '\n';

  // Persistent, and idempotent: a restart finds the subscription an earlier run wrote.
  tn::Pattern heart_rate;
  heart_rate.p = tn::Term::iri(kTv + "heartRate");
  if (auto subscribed = agent->subscribe(heart_rate); !subscribed)
    return report("subscribe", subscribed.error());
  return run(*agent, *options);
}
