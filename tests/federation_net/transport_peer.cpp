// tahvel_transport_peer: the other process of wire_process_test.cpp. Opens an endpoint of the
// LCM or DDS binding, sends COUNT frames to TO right after opening (each once: no resend), then,
// with "echo", sends every frame it receives back to its sender until a `error` frame arrives or
// nothing comes for 10 s. Exit status 0 on success; errors to stderr with status 1.
//
// Usage: tahvel_transport_peer lcm|dds SELF_IRI TO_IRI COUNT [echo]
#include <cstdlib>
#include <iostream>
#include <string>

#include "wire_settings.h"

using namespace tahvel::federation;

int main(int argc, char** argv) {
  if (argc < 5) {
    std::cerr << "usage: tahvel_transport_peer lcm|dds SELF_IRI TO_IRI COUNT [echo]\n";
    return 2;
  }
  const std::string binding = argv[1], self = argv[2], to = argv[3];
  const int count = std::atoi(argv[4]);
  const bool echo = argc > 5 && std::string(argv[5]) == "echo";
  auto opened = binding == "lcm" ? open_lcm(conformance::test_lcm_settings(), self)
                                 : open_dds(conformance::test_dds_settings(), self);
  if (!opened) {
    std::cerr << "tahvel_transport_peer: " << opened.error().message << "\n";
    return 1;
  }
  Transport& t = **opened;
  for (int i = 1; i <= count; ++i) {
    Frame f;
    f.kind = FrameKind::up;
    f.from = self;
    f.to = to;
    f.seq = static_cast<std::uint64_t>(i);
    f.body = "peer " + std::to_string(i);
    if (auto sent = t.send(f); !sent) {
      std::cerr << "tahvel_transport_peer: " << sent.error().message << "\n";
      return 1;
    }
  }
  while (echo) {
    auto got = t.receive(std::chrono::seconds(10));
    if (!got) {
      std::cerr << "tahvel_transport_peer: " << got.error().message << "\n";
      return 1;
    }
    if (!*got || (*got)->kind == FrameKind::error) break;
    Frame back = std::move(**got);
    std::swap(back.from, back.to);
    if (auto sent = t.send(back); !sent) {
      std::cerr << "tahvel_transport_peer: " << sent.error().message << "\n";
      return 1;
    }
  }
  return 0;
}
