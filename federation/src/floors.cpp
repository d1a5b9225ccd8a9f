// Raw LCM and Cyclone DDS ping-pong latency (floors.h): the library alone, a two-int64 message.
// The echo side answers every ping; the ping side sends one ping at a time and waits for its
// pong. Both sides run in one process (raw_*_pingpong: two threads) or in two (the halves).
#include "tahvel/federation/floors.h"

#include <dds/dds.h>
#include <lcm/lcm.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <vector>

#include "dds_domain.h"
#include "tahvel_ping.h"
#include "tahvel_ping_t.h"

namespace tahvel::federation {
namespace {

using clock = std::chrono::steady_clock;

double micros(clock::duration d) { return std::chrono::duration<double, std::micro>(d).count(); }

// The q-quantile of `sorted` (ascending, not empty): the nearest rank.
double quantile(const std::vector<double>& sorted, double q) {
  const std::size_t n = sorted.size();
  std::size_t i = static_cast<std::size_t>(std::ceil(q * static_cast<double>(n)));
  return sorted[std::min(n - 1, i == 0 ? 0 : i - 1)];
}

LatencyFloor summarise(std::vector<double> one_way_us, std::vector<double> legs_us = {}) {
  std::sort(one_way_us.begin(), one_way_us.end());
  LatencyFloor f;
  f.rounds = static_cast<int>(one_way_us.size());
  f.p50_us = quantile(one_way_us, 0.50);
  f.p99_us = quantile(one_way_us, 0.99);
  f.one_way_us = std::move(one_way_us);
  // Both legs of every round, or none: a round whose stamp fell outside it leaves them all out.
  if (legs_us.size() == 2 * f.one_way_us.size()) {
    std::sort(legs_us.begin(), legs_us.end());
    f.leg_p50_us = quantile(legs_us, 0.50);
    f.leg_p99_us = quantile(legs_us, 0.99);
    f.legs_us = std::move(legs_us);
  }
  return f;
}

std::int64_t stamp_ns(clock::time_point t) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
}

// Adds the two legs of a round sent at `t0` and answered at `t3`, split at the echo's `taken_ns`,
// when the stamp lies within the round (the echo on this machine's clock).
void add_legs(std::vector<double>& legs, clock::time_point t0, clock::time_point t3, std::int64_t taken_ns) {
  if (taken_ns < stamp_ns(t0) || taken_ns > stamp_ns(t3)) return;
  const clock::time_point taken{std::chrono::nanoseconds(taken_ns)};
  legs.push_back(micros(taken - t0));
  legs.push_back(micros(t3 - taken));
}

// Names no other run on this host uses at the same time.
std::string unique_suffix() {
  static std::atomic<int> counter{0};
  return std::to_string(getpid()) + "_" + std::to_string(counter++);
}

int warmup_of(int rounds) { return std::max(10, rounds / 10); }

// ---- LCM ------------------------------------------------------------------------------------

struct LcmOwner {
  lcm_t* lcm = nullptr;
  ~LcmOwner() {
    if (lcm != nullptr) lcm_destroy(lcm);
  }
};

struct LcmEcho {
  lcm_t* lcm;
  std::string pong_channel;
  bool stop = false;
};

void lcm_echo_one(const lcm_recv_buf_t*, const char*, const tahvel_ping_t* msg, void* user) {
  auto* echo = static_cast<LcmEcho*>(user);
  if (msg->seq < 0) {
    echo->stop = true;
    return;
  }
  tahvel_ping_t pong = *msg;
  pong.taken_ns = stamp_ns(clock::now());
  tahvel_ping_t_publish(echo->lcm, echo->pong_channel.c_str(), &pong);
}

struct LcmWait {
  int64_t want = -1;
  bool got = false;
  int64_t taken_ns = 0;
};

void lcm_pong(const lcm_recv_buf_t*, const char*, const tahvel_ping_t* msg, void* user) {
  auto* wait = static_cast<LcmWait*>(user);
  if (msg->seq != wait->want) return;
  wait->got = true;
  wait->taken_ns = msg->taken_ns;
}

std::string lcm_ping_channel(const std::string& name) { return "TVFLOOR_PING_" + name; }
std::string lcm_pong_channel(const std::string& name) { return "TVFLOOR_PONG_" + name; }

}  // namespace

Result<void> lcm_echo(const LcmSettings& settings, const std::string& name,
                      const std::function<void()>& ready, std::chrono::milliseconds idle) {
  LcmOwner b{lcm_create(settings.url.c_str())};
  if (b.lcm == nullptr) return node::fail(Errc::io, "lcm_echo: lcm_create failed for " + settings.url);
  LcmEcho echo{b.lcm, lcm_pong_channel(name)};
  tahvel_ping_t_subscription_t* sub =
      tahvel_ping_t_subscribe(b.lcm, lcm_ping_channel(name).c_str(), &lcm_echo_one, &echo);
  if (ready) ready();
  auto last = clock::now();
  while (!echo.stop && clock::now() - last < idle) {
    if (lcm_handle_timeout(b.lcm, 50) > 0) last = clock::now();
  }
  tahvel_ping_t_unsubscribe(b.lcm, sub);
  return {};
}

Result<LatencyFloor> lcm_ping(const LcmSettings& settings, const std::string& name, int rounds) {
  if (rounds <= 0) return node::fail(Errc::invalid_argument, "lcm ping-pong: rounds must be > 0");
  LcmOwner a{lcm_create(settings.url.c_str())};
  if (a.lcm == nullptr) return node::fail(Errc::io, "lcm ping-pong: lcm_create failed for " + settings.url);
  const std::string ping = lcm_ping_channel(name);
  LcmWait wait;
  tahvel_ping_t_subscription_t* pong_sub =
      tahvel_ping_t_subscribe(a.lcm, lcm_pong_channel(name).c_str(), &lcm_pong, &wait);
  const int warmup = warmup_of(rounds), max_losses = rounds / 10 + 10;
  int losses = 0;
  std::vector<double> samples, legs;
  samples.reserve(static_cast<std::size_t>(rounds));
  for (int64_t seq = 0; static_cast<int>(samples.size()) < rounds && losses <= max_losses; ++seq) {
    wait.want = seq;
    wait.got = false;
    tahvel_ping_t msg{seq, 0};
    const auto t0 = clock::now();
    const auto deadline = t0 + std::chrono::seconds(1);
    tahvel_ping_t_publish(a.lcm, ping.c_str(), &msg);
    while (!wait.got && clock::now() < deadline) {
      auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - clock::now());
      lcm_handle_timeout(a.lcm, static_cast<int>(std::max<long long>(1, left.count())));
    }
    if (!wait.got) {
      ++losses;
      continue;
    }
    const auto t3 = clock::now();
    if (seq >= warmup) {
      samples.push_back(micros(t3 - t0) / 2);
      add_legs(legs, t0, t3, wait.taken_ns);
    }
  }
  // The echo stops at this ping (or after its idle time if LCM drops all three).
  tahvel_ping_t stop{-1, 0};
  for (int i = 0; i < 3; ++i) tahvel_ping_t_publish(a.lcm, ping.c_str(), &stop);
  tahvel_ping_t_unsubscribe(a.lcm, pong_sub);
  if (static_cast<int>(samples.size()) < rounds) {
    return node::fail(Errc::timeout, "lcm ping-pong on " + settings.url + ": " + std::to_string(losses) +
                                         " pings without a pong within 1 s");
  }
  return summarise(std::move(samples), std::move(legs));
}

Result<LatencyFloor> raw_lcm_pingpong(const LcmSettings& settings, int rounds) {
  if (rounds <= 0) return node::fail(Errc::invalid_argument, "raw_lcm_pingpong: rounds must be > 0");
  const std::string name = unique_suffix();
  std::mutex mu;
  std::condition_variable cv;
  bool listening = false;
  Result<void> echoed{};
  std::thread echoer([&] {
    echoed = lcm_echo(settings, name, [&] {
      std::lock_guard lock(mu);
      listening = true;
      cv.notify_all();
    }, std::chrono::seconds(2));
    std::lock_guard lock(mu);
    listening = true;  // also when it failed before listening
    cv.notify_all();
  });
  {
    std::unique_lock lock(mu);
    cv.wait(lock, [&] { return listening; });
  }
  auto floor = lcm_ping(settings, name, rounds);
  echoer.join();
  if (!echoed) return node::fail(echoed.error().code, echoed.error().message);
  return floor;
}

// ---- Cyclone DDS ----------------------------------------------------------------------------

namespace {

// A participant of its own, on a domain joined for as long as it lives.
struct DdsParticipant {
  dds_domainid_t domain;
  bool joined = false;
  dds_entity_t pp = 0;
  ~DdsParticipant() {
    if (pp > 0) dds_delete(pp);
    if (joined) dds_domain::release(domain);
  }
};

Result<void> join(DdsParticipant& p, const DdsSettings& settings, const char* who) {
  if (auto ok = dds_domain::acquire(settings.domain, settings.config); !ok)
    return node::fail(ok.error().code, std::string(who) + ": " + ok.error().message);
  p.joined = true;
  p.pp = dds_create_participant(settings.domain, nullptr, nullptr);
  if (p.pp < 0) return node::fail(Errc::io, std::string(who) + ": participant: " + dds_domain::retcode(p.pp));
  return {};
}

dds_entity_t make_endpoint(dds_entity_t pp, const std::string& topic_name, bool writer) {
  dds_entity_t topic =
      dds_create_topic(pp, &tahvel_Ping_desc, topic_name.c_str(), nullptr, nullptr);
  if (topic < 0) return topic;
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
  dds_entity_t e = writer ? dds_create_writer(pp, topic, qos, nullptr)
                          : dds_create_reader(pp, topic, qos, nullptr);
  dds_delete_qos(qos);
  return e;
}

// Waits on `entity`'s publication- (writer) or subscription-matched (reader) status until it has
// matched the other side, up to `limit`. A sample written before its writer matched a reader is
// lost (volatile durability): each side waits before its first write.
bool matched(dds_entity_t pp, dds_entity_t entity, bool writer, std::chrono::seconds limit) {
  const uint32_t mask = writer ? DDS_PUBLICATION_MATCHED_STATUS : DDS_SUBSCRIPTION_MATCHED_STATUS;
  dds_set_status_mask(entity, mask);
  dds_entity_t ws = dds_create_waitset(pp);
  dds_waitset_attach(ws, entity, 0);
  const auto deadline = clock::now() + limit;
  bool ok = false;
  for (;;) {
    if (writer) {
      dds_publication_matched_status_t st{};
      if (dds_get_publication_matched_status(entity, &st) < 0) break;
      ok = st.current_count > 0;
    } else {
      dds_subscription_matched_status_t st{};
      if (dds_get_subscription_matched_status(entity, &st) < 0) break;
      ok = st.current_count > 0;
    }
    if (ok) break;
    auto left = std::chrono::duration_cast<std::chrono::nanoseconds>(deadline - clock::now());
    if (left.count() <= 0) break;
    dds_waitset_wait(ws, nullptr, 0, left.count());
  }
  dds_delete(ws);
  return ok;
}

// Takes one sample from `reader` into `out`, waiting on `ws` until `deadline`.
bool take_one(dds_entity_t reader, dds_entity_t ws, clock::time_point deadline, tahvel_Ping* out) {
  for (;;) {
    void* sample = out;
    dds_sample_info_t info;
    dds_return_t n = dds_take(reader, &sample, &info, 1, 1);
    if (n < 0) return false;
    if (n == 1 && info.valid_data) return true;
    if (n == 1) continue;
    auto left = std::chrono::duration_cast<std::chrono::nanoseconds>(deadline - clock::now());
    if (left.count() <= 0) return false;
    dds_waitset_wait(ws, nullptr, 0, left.count());
  }
}

std::string dds_ping_topic(const std::string& name) { return "tahvel_floor_ping_" + name; }
std::string dds_pong_topic(const std::string& name) { return "tahvel_floor_pong_" + name; }

}  // namespace

Result<void> dds_echo(const DdsSettings& settings, const std::string& name,
                      const std::function<void()>& ready, std::chrono::milliseconds idle) {
  DdsParticipant b{settings.domain};
  if (auto ok = join(b, settings, "dds_echo"); !ok) return ok;
  dds_entity_t ping_r = make_endpoint(b.pp, dds_ping_topic(name), false),
               pong_w = make_endpoint(b.pp, dds_pong_topic(name), true);
  if (ping_r < 0 || pong_w < 0)
    return node::fail(Errc::io, "dds_echo: endpoint: " + dds_domain::retcode(ping_r < 0 ? ping_r : pong_w));
  if (ready) ready();
  if (!matched(b.pp, pong_w, true, std::chrono::seconds(10)))
    return node::fail(Errc::timeout, "dds_echo: no reader of the pong topic within 10 s");
  dds_entity_t ws = dds_create_waitset(b.pp);
  dds_waitset_attach(ws, dds_create_readcondition(ping_r, DDS_ANY_STATE), 0);
  auto last = clock::now();
  for (;;) {
    tahvel_Ping msg{};
    if (!take_one(ping_r, ws, clock::now() + std::chrono::milliseconds(50), &msg)) {
      if (clock::now() - last >= idle) break;
      continue;
    }
    last = clock::now();
    if (msg.seq < 0) break;
    msg.taken_ns = stamp_ns(last);
    dds_write(pong_w, &msg);
    dds_write_flush(pong_w);  // sent now also under Internal/WriteBatch (our configurations)
  }
  return {};
}

Result<LatencyFloor> dds_ping(const DdsSettings& settings, const std::string& name, int rounds) {
  if (rounds <= 0) return node::fail(Errc::invalid_argument, "dds ping-pong: rounds must be > 0");
  DdsParticipant a{settings.domain};
  if (auto ok = join(a, settings, "dds ping-pong"); !ok) return node::fail(ok.error().code, ok.error().message);
  dds_entity_t ping_w = make_endpoint(a.pp, dds_ping_topic(name), true),
               pong_r = make_endpoint(a.pp, dds_pong_topic(name), false);
  if (ping_w < 0 || pong_r < 0)
    return node::fail(Errc::io, "dds ping-pong: endpoint: " + dds_domain::retcode(ping_w < 0 ? ping_w : pong_r));
  if (!matched(a.pp, ping_w, true, std::chrono::seconds(10)) || !matched(a.pp, pong_r, false, std::chrono::seconds(10)))
    return node::fail(Errc::timeout, "dds ping-pong: the echo's endpoints did not match within 10 s");
  dds_entity_t ws = dds_create_waitset(a.pp);
  dds_waitset_attach(ws, dds_create_readcondition(pong_r, DDS_ANY_STATE), 0);
  const int warmup = warmup_of(rounds);
  std::vector<double> samples, legs;
  samples.reserve(static_cast<std::size_t>(rounds));
  bool lost = false;
  for (int64_t seq = 0; static_cast<int>(samples.size()) < rounds && !lost; ++seq) {
    tahvel_Ping msg{seq, 0}, answer{-1, 0};
    const auto t0 = clock::now();
    const auto deadline = t0 + std::chrono::seconds(5);
    if (dds_write(ping_w, &msg) < 0) lost = true;
    dds_write_flush(ping_w);
    while (!lost && answer.seq != seq) {
      if (!take_one(pong_r, ws, deadline, &answer)) lost = true;
    }
    const auto t3 = clock::now();
    if (!lost && seq >= warmup) {
      samples.push_back(micros(t3 - t0) / 2);
      add_legs(legs, t0, t3, answer.taken_ns);
    }
  }
  tahvel_Ping stop{-1, 0};
  dds_write(ping_w, &stop);
  dds_write_flush(ping_w);
  if (lost) return node::fail(Errc::timeout, "dds ping-pong: no pong within 5 s");
  return summarise(std::move(samples), std::move(legs));
}

Result<LatencyFloor> raw_dds_pingpong(const DdsSettings& settings, int rounds) {
  if (rounds <= 0) return node::fail(Errc::invalid_argument, "raw_dds_pingpong: rounds must be > 0");
  const std::string name = unique_suffix();
  Result<void> echoed{};
  std::thread echoer([&] { echoed = dds_echo(settings, name, {}, std::chrono::seconds(15)); });
  auto floor = dds_ping(settings, name, rounds);
  echoer.join();
  if (!floor) return floor;
  if (!echoed) return node::fail(echoed.error().code, echoed.error().message);
  return floor;
}

// ---- Through the bindings --------------------------------------------------------------------

Result<void> binding_echo(Transport& endpoint, std::chrono::milliseconds idle) {
  for (;;) {
    auto got = endpoint.receive(idle);
    if (!got) return node::fail(got.error().code, "binding echo: " + got.error().message);
    if (!*got || (*got)->kind == FrameKind::error) return {};
    Frame back = std::move(**got);
    back.to = std::move(back.from);
    back.from = endpoint.self();
    if (auto sent = endpoint.send(back); !sent) return node::fail(sent.error().code, "binding echo: " + sent.error().message);
  }
}

Result<LatencyFloor> binding_ping(Transport& endpoint, const std::string& echo_iri, int rounds, std::size_t body_bytes) {
  if (rounds <= 0) return node::fail(Errc::invalid_argument, "binding ping-pong: rounds must be > 0");
  const int warmup = warmup_of(rounds), max_losses = rounds / 10 + 10;
  int losses = 0, measured = 0;
  std::vector<double> samples;
  samples.reserve(static_cast<std::size_t>(rounds));
  Frame ping;
  ping.kind = FrameKind::up;
  ping.from = endpoint.self();
  ping.to = echo_iri;
  ping.body.assign(body_bytes, 'x');
  for (std::uint64_t seq = 1; measured < rounds && losses <= max_losses; ++seq) {
    ping.seq = seq;
    const auto t0 = clock::now();
    const auto deadline = t0 + std::chrono::seconds(1);
    if (auto sent = endpoint.send(ping); !sent) return node::fail(sent.error().code, "binding ping-pong: " + sent.error().message);
    bool back = false;
    while (!back) {
      const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - clock::now());
      if (left.count() <= 0) break;
      auto got = endpoint.receive(left);
      if (!got) return node::fail(got.error().code, "binding ping-pong: " + got.error().message);
      back = *got && (*got)->seq == seq;  // an earlier ping's late answer is skipped
    }
    if (!back) {
      ++losses;
      continue;
    }
    if (static_cast<int>(seq) - losses > warmup) {
      samples.push_back(micros(clock::now() - t0) / 2);
      ++measured;
    }
  }
  Frame stop = ping;
  stop.kind = FrameKind::error;
  stop.body.clear();
  for (int i = 0; i < 3; ++i) (void)endpoint.send(stop);  // LCM may drop one
  if (measured < rounds)
    return node::fail(Errc::timeout, "binding ping-pong to <" + echo_iri + ">: " + std::to_string(losses) +
                                         " frames without an answer within 1 s");
  return summarise(std::move(samples));
}

}  // namespace tahvel::federation
