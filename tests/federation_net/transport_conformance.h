// Transport conformance suite (transport.h): the cases every binding of Transport must pass,
// as a parameterized GoogleTest fixture. A test binary instantiates it once per binding:
//
//   INSTANTIATE_TEST_SUITE_P(Lcm, TransportConformance, ::testing::Values(Binding{...}),
//                            BindingName);
//
// Include this header from exactly one .cpp of a test binary (it defines the TEST_P cases).
// Bindings that send packets must run inside a private network namespace (tests/tools/netns-run);
// Binding::needs_netns makes every case fail outside one instead of touching the host network.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <functional>
#include <iostream>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "tahvel/federation/transport.h"

namespace tahvel::federation::conformance {

using namespace std::chrono_literals;

struct Binding {
  std::string name;  // the instantiation's name: letters and digits only
  // Opens an endpoint bound to `iri` whose drop lines go to `log`; nullptr fails the case.
  std::function<std::unique_ptr<Transport>(std::string iri, DropLog log)> open;
  // Puts raw bytes where the endpoint bound to `to` reads them (the LCM channel, the memory
  // bus's decode path). Empty when the binding cannot carry arbitrary bytes to the endpoint.
  std::function<void(const std::string& to, const std::string& bytes)> inject_raw;
  // Why inject_raw is empty (printed when the garbage case is skipped).
  std::string no_raw_reason;
  // True when every frame whose send() succeeded is delivered (DDS reliable, memory without
  // faults); false when frames may be lost (LCM).
  bool lossless = false;
  bool needs_netns = true;
  // True when the binding receives on a thread of its own and offers push mode
  // (Transport::on_arrival): Cyclone DDS.
  bool pushes = false;
};

// Test names show the binding's name, not its bytes.
inline void PrintTo(const Binding& binding, std::ostream* os) { *os << binding.name; }

inline std::string BindingName(const ::testing::TestParamInfo<Binding>& info) {
  return info.param.name;
}

// Drop lines of one endpoint, collected from whichever thread the binding logs on.
class DropLines {
 public:
  DropLog sink() {
    return [this](std::string_view line) {
      std::lock_guard lock(mutex_);
      lines_.emplace_back(line);
    };
  }
  std::vector<std::string> lines() const {
    std::lock_guard lock(mutex_);
    return lines_;
  }
  std::size_t size() const {
    std::lock_guard lock(mutex_);
    return lines_.size();
  }

 private:
  mutable std::mutex mutex_;
  std::vector<std::string> lines_;
};

struct Endpoint {
  std::unique_ptr<DropLines> drops = std::make_unique<DropLines>();
  std::unique_ptr<Transport> transport;
  Transport* operator->() const { return transport.get(); }
  Transport& operator*() const { return *transport; }
};

inline Frame make_frame(const Transport& from, const Transport& to, FrameKind kind,
                        std::uint64_t seq, std::string body) {
  Frame f;
  f.kind = kind;
  f.from = from.self();
  f.to = to.self();
  f.seq = seq;
  f.prev = seq == 0 ? 0 : seq - 1;
  f.ack = 0;
  f.body = std::move(body);
  return f;
}

inline std::string all_byte_values() {
  std::string s;
  for (int round = 0; round < 4; ++round) {
    for (int b = 0; b < 256; ++b) s += static_cast<char>(b);
  }
  return s;
}

// Deterministic pseudo-random bytes (xorshift), NULs included.
inline std::string noise(std::size_t n, std::uint64_t seed) {
  std::string s(n, '\0');
  std::uint64_t x = seed * 0x9e3779b97f4a7c15ull + 1;
  for (auto& c : s) {
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    c = static_cast<char>(x >> 56);
  }
  return s;
}

inline void expect_same(const Frame& want, const Frame& got) {
  EXPECT_EQ(want.version, got.version);
  EXPECT_EQ(want.fingerprint, got.fingerprint);
  EXPECT_EQ(want.kind, got.kind);
  EXPECT_EQ(want.from, got.from);
  EXPECT_EQ(want.to, got.to);
  EXPECT_EQ(want.seq, got.seq);
  EXPECT_EQ(want.prev, got.prev);
  EXPECT_EQ(want.ack, got.ack);
  EXPECT_EQ(want.body.size(), got.body.size());
  EXPECT_TRUE(want.body == got.body) << "body differs (" << want.body.size() << " bytes)";
}

class TransportConformance : public ::testing::TestWithParam<Binding> {
 protected:
  void SetUp() override {
    if (GetParam().needs_netns) {
      const char* in = std::getenv("TAHVEL_IN_NETNS");
      ASSERT_TRUE(in != nullptr && std::string(in) == "1")
          << "the " << GetParam().name << " binding sends packets: run this test under "
          << "tests/tools/netns-run (a private network namespace with loopback only)";
    }
  }

  // An endpoint with an IRI no other case or process uses.
  Endpoint open(const std::string& name) {
    static std::atomic<int> counter{0};
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string test = info->name();
    for (auto& c : test) {
      if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
    }
    std::string iri = "tahvel://conformance/" + std::to_string(getpid()) + "-" +
                      std::to_string(counter++) + "/" + test + "/" + name;
    Endpoint e;
    e.transport = GetParam().open(iri, e.drops->sink());
    return e;
  }

  // The next frame at `to`, or nullopt after `timeout`; fails the case on a receive error.
  static std::optional<Frame> next(Endpoint& to, std::chrono::milliseconds timeout) {
    auto got = to->receive(timeout);
    EXPECT_TRUE(got) << (got ? "" : got.error().message);
    if (!got) return std::nullopt;
    return std::move(*got);
  }

  // Sends `frame` from `from` and returns what `to` receives first. A lossless binding sends
  // once; a lossy one resends (up to 5 times, 2 s apart) as the link would.
  std::optional<Frame> deliver(Endpoint& from, Endpoint& to, const Frame& frame) {
    const int attempts = GetParam().lossless ? 1 : 5;
    for (int i = 0; i < attempts; ++i) {
      auto sent = from->send(frame);
      EXPECT_TRUE(sent) << (sent ? "" : sent.error().message);
      if (!sent) return std::nullopt;
      if (auto got = next(to, GetParam().lossless ? 10s : 2s)) return got;
    }
    return std::nullopt;
  }

  // Calls receive() on `at` until it has logged `n` drop lines or `timeout` passed; every frame
  // it returns meanwhile goes to `frames`.
  static void drain_until_drops(Endpoint& at, std::size_t n, std::chrono::milliseconds timeout,
                                std::vector<Frame>* frames) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (at.drops->size() < n && std::chrono::steady_clock::now() < deadline) {
      if (auto got = next(at, 50ms)) frames->push_back(std::move(*got));
    }
  }
};

// Every field survives, with extreme values, binary bytes with NULs, and a 2 MB body.
TEST_P(TransportConformance, FrameRoundTripsFieldForField) {
  Endpoint a = open("a"), b = open("b");
  ASSERT_TRUE(a.transport && b.transport);
  Frame small = make_frame(*a, *b, FrameKind::up, 0xfedcba9876543210ull, all_byte_values());
  small.prev = 0xffffffffffffffffull;
  small.ack = 0x8000000000000001ull;
  Frame empty = make_frame(*a, *b, FrameKind::ack, 1, "");
  Frame large = make_frame(*a, *b, FrameKind::answer, 2, noise(2u << 20, 7));
  for (const Frame* f : {&small, &empty, &large}) {
    auto got = deliver(a, b, *f);
    ASSERT_TRUE(got) << "no frame of " << f->body.size() << " bytes arrived";
    expect_same(*f, *got);
  }
  EXPECT_EQ(b.drops->size(), 0u);
}

// Each kind arrives as itself.
TEST_P(TransportConformance, EveryKindArrives) {
  Endpoint a = open("a"), b = open("b");
  ASSERT_TRUE(a.transport && b.transport);
  for (int k = 1; k <= 9; ++k) {
    Frame f = make_frame(*a, *b, static_cast<FrameKind>(k), static_cast<std::uint64_t>(k), "k");
    auto got = deliver(a, b, f);
    ASSERT_TRUE(got) << "kind " << k;
    EXPECT_EQ(got->kind, f.kind);
    EXPECT_EQ(got->seq, f.seq);
  }
}

// A frame reaches only the endpoint bound to its `to`: a third endpoint gets nothing.
TEST_P(TransportConformance, FramesGoOnlyToTheAddressee) {
  Endpoint a = open("a"), b = open("b"), c = open("c");
  ASSERT_TRUE(a.transport && b.transport && c.transport);
  for (std::uint64_t i = 1; i <= 20; ++i) {
    ASSERT_TRUE(a->send(make_frame(*a, *b, FrameKind::up, i, "for b")));
  }
  // A marker for c sent after b's frames: once c has it, b's frames have had their chance.
  auto marker = deliver(a, c, make_frame(*a, *c, FrameKind::down, 99, "for c"));
  ASSERT_TRUE(marker);
  EXPECT_EQ(marker->body, "for c");
  std::set<std::uint64_t> at_b;
  while (auto got = next(b, 500ms)) {
    EXPECT_EQ(got->body, "for b");
    EXPECT_EQ(got->to, b->self());
    at_b.insert(got->seq);
  }
  EXPECT_FALSE(at_b.empty());
  if (GetParam().lossless) {
    EXPECT_EQ(at_b.size(), 20u);
  }
  auto stray = next(c, 300ms);
  EXPECT_FALSE(stray) << "c received a frame addressed to " << stray->to;
  EXPECT_EQ(c.drops->size(), 0u) << "c saw (and dropped) traffic for b: " << c.drops->lines()[0];
}

// Bytes that are not a frame are dropped with a logged reason; the endpoint keeps working.
TEST_P(TransportConformance, GarbageIsDroppedWithAReasonAndTheEndpointKeepsWorking) {
  if (!GetParam().inject_raw) GTEST_SKIP() << GetParam().no_raw_reason;
  Endpoint a = open("a"), b = open("b");
  ASSERT_TRUE(a.transport && b.transport);
  const std::vector<std::string> garbage = {
      std::string(),  std::string(1, '\0'), "hello, this is not a frame",
      noise(1000, 3), noise(70000, 4),  // more than one UDP datagram's worth
  };
  for (const auto& bytes : garbage) GetParam().inject_raw(b->self(), bytes);
  std::vector<Frame> frames;
  drain_until_drops(b, garbage.size(), 5s, &frames);
  EXPECT_TRUE(frames.empty()) << "garbage came out of receive() as a frame";
  auto lines = b.drops->lines();
  ASSERT_EQ(lines.size(), garbage.size());
  for (const auto& line : lines) {
    std::cout << "[ " << GetParam().name << " ] " << line << "\n";
    EXPECT_NE(line.find(b->self()), std::string::npos)
        << "line does not name the endpoint: " << line;
    EXPECT_EQ(line.find('\n'), std::string::npos) << "not one line: " << line;
  }
  auto got = deliver(a, b, make_frame(*a, *b, FrameKind::up, 5, "still alive"));
  ASSERT_TRUE(got);
  EXPECT_EQ(got->body, "still alive");
}

// Frames of another protocol version, another message fingerprint, or an unknown kind are
// dropped with a reason that says which; the good frame sent after them comes through.
TEST_P(TransportConformance, WrongVersionFingerprintOrKindIsDroppedWithAReason) {
  Endpoint a = open("a"), b = open("b");
  ASSERT_TRUE(a.transport && b.transport);
  Frame version = make_frame(*a, *b, FrameKind::up, 1, "v");
  version.version = kProtocolVersion + 1;
  Frame fingerprint = make_frame(*a, *b, FrameKind::up, 2, "f");
  fingerprint.fingerprint = message_fingerprint() ^ 1;
  Frame kind = make_frame(*a, *b, FrameKind::up, 3, "k");
  kind.kind = static_cast<FrameKind>(200);
  for (const Frame* f : {&version, &fingerprint, &kind}) ASSERT_TRUE(a->send(*f));
  std::vector<Frame> frames;
  drain_until_drops(b, 3, 10s, &frames);
  EXPECT_TRUE(frames.empty()) << "a bad frame came out of receive(): seq " << frames[0].seq;
  auto lines = b.drops->lines();
  ASSERT_EQ(lines.size(), 3u);
  std::string all;
  for (const auto& l : lines) {
    std::cout << "[ " << GetParam().name << " ] " << l << "\n";
    all += l + "\n";
  }
  EXPECT_NE(all.find("version " + std::to_string(kProtocolVersion + 1)), std::string::npos) << all;
  EXPECT_NE(all.find("fingerprint"), std::string::npos) << all;
  EXPECT_NE(all.find("kind 200 unknown"), std::string::npos) << all;
  EXPECT_NE(all.find(a->self()), std::string::npos) << "lines do not name the sender: " << all;
  auto got = deliver(a, b, make_frame(*a, *b, FrameKind::up, 4, "good"));
  ASSERT_TRUE(got);
  EXPECT_EQ(got->body, "good");
}

// receive() with nothing to receive returns nullopt, not before its timeout.
TEST_P(TransportConformance, ReceiveTimesOutWithNullopt) {
  Endpoint a = open("a");
  ASSERT_TRUE(a.transport);
  auto zero = a->receive(0ms);
  ASSERT_TRUE(zero) << zero.error().message;
  EXPECT_FALSE(*zero);
  const auto t0 = std::chrono::steady_clock::now();
  auto got = a->receive(200ms);
  ASSERT_TRUE(got) << got.error().message;
  EXPECT_FALSE(*got);
  EXPECT_GE(std::chrono::steady_clock::now() - t0, 200ms);
}

// send() from one thread while another thread is in receive() on the same endpoint.
TEST_P(TransportConformance, SendWhileReceivingOnTheSameEndpoint) {
  Endpoint a = open("a"), b = open("b");
  ASSERT_TRUE(a.transport && b.transport);
  constexpr int kFrames = 200;
  std::atomic<bool> done{false};
  std::mutex mutex;
  std::condition_variable changed;
  std::vector<Frame> echoes;  // guarded by mutex
  std::thread receiver([&] {
    while (!done.load()) {
      auto got = a->receive(20ms);
      if (!got || !*got) continue;
      std::lock_guard lock(mutex);
      echoes.push_back(std::move(**got));
      changed.notify_all();
    }
  });
  std::thread echoer([&] {
    for (int n = 0; n < kFrames && !done.load();) {
      auto got = b->receive(20ms);
      if (!got || !*got) continue;
      ++n;
      Frame back = **got;
      std::swap(back.from, back.to);
      (void)b->send(back);
    }
  });
  for (int i = 0; i < kFrames; ++i) {
    ASSERT_TRUE(a->send(make_frame(*a, *b, FrameKind::query, static_cast<std::uint64_t>(i),
                                   "echo " + std::to_string(i))));
  }
  {
    // All echoes, or 3 s without a new one (a lossy binding may lose some).
    std::unique_lock lock(mutex);
    std::size_t before = 0;
    do {
      before = echoes.size();
      changed.wait_for(lock, 3s, [&] { return echoes.size() >= kFrames; });
    } while (echoes.size() < kFrames && echoes.size() > before);
  }
  done = true;
  receiver.join();
  echoer.join();
  for (const auto& f : echoes) {
    EXPECT_EQ(f.to, a->self());
    EXPECT_EQ(f.body, "echo " + std::to_string(f.seq));
  }
  EXPECT_FALSE(echoes.empty());
  if (GetParam().lossless) {
    EXPECT_EQ(echoes.size(), static_cast<std::size_t>(kFrames));
  }
  EXPECT_EQ(a.drops->size(), 0u);
  EXPECT_EQ(b.drops->size(), 0u);
}

// 10,000 frames sent as fast as send() returns. What arrives is intact; nothing bogus is
// logged; a lossless binding delivers every frame whose send() succeeded.
// A run of frames marked kMoreFollow (P9b), their bodies from empty to larger than a DDS pack
// (14,000 bytes), with an ack to the same endpoint in the middle of it, arrives field for field
// and in the order sent; on a lossless binding, all of it. (The DDS binding packs such a run
// into few samples; the ack must not overtake the frames before it.)
TEST_P(TransportConformance, ARunOfFramesArrivesIntactAndInOrderWithAnotherFrameAmongThem) {
  Endpoint a = open("a"), b = open("b");
  ASSERT_TRUE(a.transport && b.transport);
  const std::size_t sizes[] = {0, 1, 600, 580, 7000, 13000, 20000, 3, 13971, 14000};
  std::vector<Frame> sent;
  for (std::uint64_t i = 0; i < 40; ++i) {
    if (i == 10) {
      Frame ack = make_frame(*a, *b, FrameKind::ack, 0, "");
      ack.ack = 7;
      sent.push_back(ack);
    }
    Frame f = make_frame(*a, *b, i < 20 ? FrameKind::up : FrameKind::down, i + 1, noise(sizes[i % 10], i));
    f.ack = (i == 19 || i == 39) ? kAckNow : kMoreFollow;
    sent.push_back(std::move(f));
  }
  for (const Frame& f : sent) ASSERT_TRUE(a->send(f));
  std::vector<Frame> got;
  while (got.size() < sent.size()) {
    auto f = next(b, GetParam().lossless ? 10s : 2s);
    if (!f) break;
    got.push_back(std::move(*f));
  }
  EXPECT_EQ(b.drops->size(), 0u) << b.drops->lines()[0];
  std::size_t at = 0;  // each arrival is a frame sent after the one before it, unchanged
  for (const Frame& f : got) {
    while (at < sent.size() && !(sent[at].kind == f.kind && sent[at].seq == f.seq)) ++at;
    ASSERT_LT(at, sent.size()) << "kind " << static_cast<int>(f.kind) << " seq " << f.seq << " out of order";
    expect_same(sent[at], f);
    ++at;
  }
  if (GetParam().lossless) {
    EXPECT_EQ(got.size(), sent.size());
  }
}

TEST_P(TransportConformance, BurstOfTenThousandFramesArrivesIntact) {
  Endpoint a = open("a"), b = open("b");
  ASSERT_TRUE(a.transport && b.transport);
  constexpr std::uint64_t kFrames = 10000;
  std::atomic<std::uint64_t> sent{0}, refused{0};
  std::thread sender([&] {
    for (std::uint64_t i = 0; i < kFrames; ++i) {
      if (a->send(make_frame(*a, *b, FrameKind::up, i, "frame " + std::to_string(i)))) {
        ++sent;
      } else {
        ++refused;
      }
    }
  });
  std::set<std::uint64_t> seen;
  std::size_t received = 0, damaged = 0;
  for (;;) {
    auto got = next(b, 2s);  // ends 2 s after the last arrival
    if (!got) break;
    ++received;
    if (got->body != "frame " + std::to_string(got->seq) || got->from != a->self() ||
        got->to != b->self() || got->kind != FrameKind::up) {
      ++damaged;
    }
    seen.insert(got->seq);
    if (seen.size() == kFrames) break;
  }
  sender.join();
  std::cout << "[ " << GetParam().name << " ] burst: " << sent << " sent, " << refused
            << " refused by send(), " << seen.size() << " distinct arrived (" << received
            << " received in all)\n";
  RecordProperty("sent", static_cast<int>(sent.load()));
  RecordProperty("arrived", static_cast<int>(seen.size()));
  EXPECT_EQ(damaged, 0u);
  EXPECT_GT(seen.size(), 0u);
  EXPECT_LE(*seen.rbegin(), kFrames - 1);
  EXPECT_EQ(b.drops->size(), 0u) << b.drops->lines()[0];
  if (GetParam().lossless) {
    EXPECT_EQ(seen.size(), sent.load());
  }
}

// Push mode (Transport::on_arrival): a binding with a receive thread of its own calls the
// function as frames arrive (there, or inside the sender's send() when Cyclone delivers within
// one process), and they can be taken there, in order; after on_arrival({}) returns no call is
// under way and frames wait for receive() again. A binding without such a thread says so, and
// receive() keeps delivering.
TEST_P(TransportConformance, OnArrivalTakesFramesOnTheBindingsThreadOrSaysItCannot) {
  Endpoint a = open("a"), b = open("b");
  ASSERT_TRUE(a.transport && b.transport);
  std::mutex mu;
  std::condition_variable arrived;
  std::vector<std::uint64_t> taken;
  const bool pushed = b->on_arrival([&] {
    for (;;) {
      auto got = b->receive(0ms);
      if (!got || !*got) return;
      std::lock_guard lock(mu);
      taken.push_back((*got)->seq);
      arrived.notify_all();
    }
  });
  ASSERT_EQ(pushed, GetParam().pushes);
  constexpr std::uint64_t kFrames = 100;
  if (!pushed) {
    auto got = deliver(a, b, make_frame(*a, *b, FrameKind::up, 1, "pulled"));
    ASSERT_TRUE(got) << "receive() no longer delivers after on_arrival said no";
    return;
  }
  for (std::uint64_t i = 1; i <= kFrames; ++i) ASSERT_TRUE(a->send(make_frame(*a, *b, FrameKind::up, i, "pushed")));
  {
    std::unique_lock lock(mu);
    ASSERT_TRUE(arrived.wait_for(lock, 10s, [&] { return taken.size() >= kFrames; }))
        << taken.size() << " of " << kFrames << " frames taken on the binding's thread";
    for (std::uint64_t i = 0; i < kFrames; ++i) EXPECT_EQ(taken[i], i + 1);
  }
  b->on_arrival({});
  ASSERT_TRUE(a->send(make_frame(*a, *b, FrameKind::up, kFrames + 1, "pulled")));
  auto got = next(b, 10s);
  ASSERT_TRUE(got) << "after on_arrival({}) the frame did not come out of receive()";
  EXPECT_EQ(got->seq, kFrames + 1);
  std::lock_guard lock(mu);
  EXPECT_EQ(taken.size(), kFrames) << "the function was called after on_arrival({}) returned";
}

}  // namespace tahvel::federation::conformance
