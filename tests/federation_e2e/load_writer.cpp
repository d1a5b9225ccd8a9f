// tahvel-e2e-load: the steady load of the failure-schedule tests (chaos_test.cpp), run as an agent
// "load" of a node under `tahvel up`. It writes numbered persistent items
//
//   <NODE#item-N> tv:loadSeq N .        (source <NODE/load>, no context)
//
// one every --every-ms, numbered 1, 2, 3, ... across restarts: after a SIGKILL the supervisor
// starts it again and it goes on after the highest number in its store, so the store holds
// exactly 1..M whatever happened. It exits 0 (finished; not restarted) once --stop-file exists.
//
//   tahvel-e2e-load STORE --every-ms 10 --stop-file PATH
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <string>
#include <thread>

#include "tahvel/node/node.h"

namespace {

const std::string kLoadSeq = "https://w3id.org/tahvel#loadSeq";

int usage() {
  std::cerr << "usage: tahvel-e2e-load STORE --every-ms N --stop-file PATH\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  using tahvel::node::Term;
  if (argc < 2) return usage();
  std::filesystem::path store = argv[1];
  int every_ms = 10;
  std::filesystem::path stop_file;
  for (int i = 2; i + 1 < argc; i += 2) {
    std::string flag = argv[i];
    if (flag == "--every-ms") every_ms = std::atoi(argv[i + 1]);
    else if (flag == "--stop-file") stop_file = argv[i + 1];
    else return usage();
  }
  if (stop_file.empty() || every_ms <= 0) return usage();
  auto node = tahvel::node::Node::open(store);
  if (!node) {
    std::cerr << "tahvel-e2e-load: " << store << ": " << node.error().message << "\n";
    return 1;
  }
  auto agent = node->agent("load");
  if (!agent) {
    std::cerr << "tahvel-e2e-load: agent load: " << agent.error().message << "\n";
    return 1;
  }
  std::int64_t n = 0;
  {
    auto snap = node->snapshot();
    if (!snap) return 1;
    auto mine = snap->list({.p = Term::iri(kLoadSeq), .source = agent->iri()});
    if (!mine) return 1;
    for (const auto& r : *mine) n = std::max<std::int64_t>(n, std::stoll(r.triple.o.value));
  }
  std::cerr << "tahvel-e2e-load <" << agent->iri() << ">: going on after item " << n << std::endl;
  const std::string subject = node->iri() + "#item-";
  auto next = std::chrono::steady_clock::now();
  while (!std::filesystem::exists(stop_file)) {
    ++n;
    tahvel::node::Item item;
    item.persistent = true;
    item.add(Term::iri(subject + std::to_string(n)), Term::iri(kLoadSeq), Term::integer(n));
    if (auto stored = agent->store(item); !stored) {
      std::cerr << "tahvel-e2e-load: item " << n << ": " << stored.error().message << std::endl;
      return 1;
    }
    next += std::chrono::milliseconds(every_ms);
    std::this_thread::sleep_until(next);
    if (std::chrono::steady_clock::now() - next > std::chrono::seconds(1)) next = std::chrono::steady_clock::now();
  }
  std::cerr << "tahvel-e2e-load <" << agent->iri() << ">: stopped after item " << n << std::endl;
  return 0;
}
