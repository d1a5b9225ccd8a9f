// Layouts other than the demo's, brought up with `tahvel up` in a private network namespace:
// a gateway that reaches its parent and its children over the same transport kind on different
// endpoints (another DDS domain, another LCM URL). Its link process then needs two endpoints of
// one kind; until the `--listen-` flags it shared the parent's, and its children never
// registered.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "tahvel/node/node.h"

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using tahvel::node::Node;
using tahvel::node::Pattern;
using tahvel::node::Term;

const std::string kBin = TAHVEL_BIN_DIR;
const std::string kWard = "http://example.org/ward-7";

int shell(const std::string& command) {
  int status = std::system(command.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::size_t ecg_chunks_from(const fs::path& store, const std::string& source) {
  auto node = Node::open(store);
  if (!node) return 0;
  auto snap = node->snapshot();
  if (!snap) return 0;
  auto records = snap->list(Pattern{.p = Term::iri("http://www.w3.org/1999/02/22-rdf-syntax-ns#type"),
                                    .o = Term::iri("https://w3id.org/tahvel#EcgChunk")});
  if (!records) return 0;
  std::size_t n = 0;
  for (const auto& r : *records) n += r.triple.s.value.rfind(source + "/", 0) == 0;
  return n;
}

struct Endpoints {
  std::string name;
  std::string ward_listen, gateway_listen;  // TOML inline tables
};

void PrintTo(const Endpoints& e, std::ostream* out) { *out << e.name; }

class SameKindTwoEndpoints : public ::testing::TestWithParam<Endpoints> {};

// ward <- gateway <- sensor, the sensor's ECG chunks forwarded all the way up: they reach the
// ward only if the gateway's link serves its child on the gateway's own endpoint.
TEST_P(SameKindTwoEndpoints, ChunksFromTheSensorReachTheTopThroughTheGateway) {
  std::string pattern = (fs::temp_directory_path() / "tahvel-layout-XXXXXX").string();
  const fs::path root = mkdtemp(pattern.data());
  const fs::path state = root / "state";
  {
    std::ofstream toml(root / "topology.toml");
    toml << "[deployment]\nname = \"layout\"\n\n"
         << "[[node]]\nid = \"ward\"\niri = \"" << kWard << "\"\ntier = \"hospital\"\nlisten = "
         << GetParam().ward_listen << "\n\n"
         << "[[node]]\nid = \"gateway\"\ntier = \"home\"\nparent = \"ward\"\nlisten = " << GetParam().gateway_listen
         << "\nforward = [\"_ a tv:EcgChunk\"]\n\n"
         << "[[node]]\nid = \"bed\"\ntier = \"sensor\"\nparent = \"gateway\"\nforward = [\"_ a tv:EcgChunk\"]\n"
         << "[[node.agent]]\nid = \"source\"\nrestart = false\n"
         << "run = [\"{bin}/tahvel-ecg-source\", \"{store}\", \"--synthetic\", \"--seed\", \"3\", \"--seconds\", \"30\", "
            "\"--speed\", \"30\"]\n";
  }
  ASSERT_EQ(shell(kBin + "/tahvel up " + (root / "topology.toml").string() + " --state " + state.string()), 0);
  const std::string sensor = kWard + "/gateway/bed";
  const auto deadline = std::chrono::steady_clock::now() + 60s;
  while (ecg_chunks_from(state / "ward", sensor) < 30 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(200ms);
  const std::size_t at_ward = ecg_chunks_from(state / "ward", sensor);
  const std::size_t at_sensor = ecg_chunks_from(state / "bed", sensor);
  shell(kBin + "/tahvel down --state " + state.string() + " >/dev/null");
  EXPECT_EQ(at_sensor, 30u) << "the sensor's 30 s of ECG in 1 s chunks";
  EXPECT_EQ(at_ward, at_sensor) << "logs in " << (state / "logs");
  std::error_code ec;
  if (!HasFailure()) fs::remove_all(root, ec);
}

const std::string kDdsConfig = std::string("config = \"") + TAHVEL_SOURCE_DIR + "/deploy/cyclonedds-loopback.xml\"";

INSTANTIATE_TEST_SUITE_P(
    Layouts, SameKindTwoEndpoints,
    ::testing::Values(Endpoints{"DdsDomains", "{ kind = \"dds\", domain = 3, " + kDdsConfig + " }",
                                "{ kind = \"dds\", domain = 4, " + kDdsConfig + " }"},
                      Endpoints{"LcmUrls", "{ kind = \"lcm\", url = \"udpm://239.255.76.67:7711?ttl=0\" }",
                                "{ kind = \"lcm\", url = \"udpm://239.255.76.68:7712?ttl=0\" }"}),
    [](const auto& info) { return info.param.name; });

}  // namespace
