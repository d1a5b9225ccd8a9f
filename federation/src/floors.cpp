// Raw LCM and Cyclone DDS ping-pong latency (floors.h): the library alone, a one-int64 message,
// two threads of this process. The answering thread echoes every ping; the measuring thread
// sends one ping at a time and waits for its pong.
#include "tahvel/federation/floors.h"

#include <dds/dds.h>
#include <lcm/lcm.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <thread>
#include <vector>

#include "dds_domain.h"
#include "tahvel_ping.h"
#include "tahvel_ping_t.h"

namespace tahvel::federation {
namespace {

using clock = std::chrono::steady_clock;

double micros(clock::duration d) { return std::chrono::duration<double, std::micro>(d).count(); }

LatencyFloor summarise(std::vector<double> one_way_us) {
  std::sort(one_way_us.begin(), one_way_us.end());
  const std::size_t n = one_way_us.size();
  auto at = [&](double q) {
    std::size_t i = static_cast<std::size_t>(std::ceil(q * static_cast<double>(n)));
    return one_way_us[std::min(n - 1, i == 0 ? 0 : i - 1)];
  };
  return LatencyFloor{at(0.50), at(0.99), static_cast<int>(n)};
}

// Names no other run on this host uses at the same time.
std::string unique_suffix() {
  static std::atomic<int> counter{0};
  return std::to_string(getpid()) + "_" + std::to_string(counter++);
}

int warmup_of(int rounds) { return std::max(10, rounds / 10); }

// ---- LCM ------------------------------------------------------------------------------------

struct LcmEcho {
  lcm_t* lcm;
  std::string pong_channel;
};

void lcm_echo(const lcm_recv_buf_t*, const char*, const tahvel_ping_t* msg, void* user) {
  auto* echo = static_cast<LcmEcho*>(user);
  tahvel_ping_t_publish(echo->lcm, echo->pong_channel.c_str(), msg);
}

struct LcmWait {
  int64_t want = -1;
  bool got = false;
};

void lcm_pong(const lcm_recv_buf_t*, const char*, const tahvel_ping_t* msg, void* user) {
  auto* wait = static_cast<LcmWait*>(user);
  if (msg->seq == wait->want) wait->got = true;
}

struct LcmOwner {
  lcm_t* lcm = nullptr;
  ~LcmOwner() {
    if (lcm != nullptr) lcm_destroy(lcm);
  }
};

}  // namespace

Result<LatencyFloor> raw_lcm_pingpong(const LcmSettings& settings, int rounds) {
  if (rounds <= 0)
    return node::fail(Errc::invalid_argument, "raw_lcm_pingpong: rounds must be > 0");
  LcmOwner a{lcm_create(settings.url.c_str())};
  LcmOwner b{lcm_create(settings.url.c_str())};
  if (a.lcm == nullptr || b.lcm == nullptr) {
    return node::fail(Errc::io, "raw_lcm_pingpong: lcm_create failed for " + settings.url);
  }
  const std::string suffix = unique_suffix();
  const std::string ping = "TVFLOOR_PING_" + suffix, pong = "TVFLOOR_PONG_" + suffix;
  LcmEcho echo{b.lcm, pong};
  LcmWait wait;
  tahvel_ping_t_subscription_t* echo_sub =
      tahvel_ping_t_subscribe(b.lcm, ping.c_str(), &lcm_echo, &echo);
  tahvel_ping_t_subscription_t* pong_sub =
      tahvel_ping_t_subscribe(a.lcm, pong.c_str(), &lcm_pong, &wait);

  std::atomic<bool> stop{false};
  std::thread echoer([&] {
    while (!stop.load()) lcm_handle_timeout(b.lcm, 20);
  });
  const int warmup = warmup_of(rounds), max_losses = rounds / 10 + 10;
  int losses = 0;
  std::vector<double> samples;
  samples.reserve(static_cast<std::size_t>(rounds));
  for (int64_t seq = 0; static_cast<int>(samples.size()) < rounds && losses <= max_losses; ++seq) {
    wait.want = seq;
    wait.got = false;
    tahvel_ping_t msg{seq};
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
    if (seq >= warmup) samples.push_back(micros(clock::now() - t0) / 2);
  }
  stop = true;
  echoer.join();
  tahvel_ping_t_unsubscribe(b.lcm, echo_sub);
  tahvel_ping_t_unsubscribe(a.lcm, pong_sub);
  if (static_cast<int>(samples.size()) < rounds) {
    return node::fail(Errc::timeout, "raw_lcm_pingpong on " + settings.url + ": " +
                                         std::to_string(losses) +
                                         " pings without a pong within 1 s");
  }
  return summarise(std::move(samples));
}

// ---- Cyclone DDS ----------------------------------------------------------------------------

namespace {

struct DdsPair {
  dds_domainid_t domain;
  dds_entity_t a = 0, b = 0;  // participants: a measures, b echoes
  ~DdsPair() {
    if (a > 0) dds_delete(a);
    if (b > 0) dds_delete(b);
    dds_domain::release(domain);
  }
};

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

// Waits on the writer's publication-matched status until it has a reader, up to 5 s.
bool matched(dds_entity_t pp, dds_entity_t writer) {
  dds_set_status_mask(writer, DDS_PUBLICATION_MATCHED_STATUS);
  dds_entity_t ws = dds_create_waitset(pp);
  dds_waitset_attach(ws, writer, 0);
  const auto deadline = clock::now() + std::chrono::seconds(5);
  bool ok = false;
  for (;;) {
    dds_publication_matched_status_t st{};
    if (dds_get_publication_matched_status(writer, &st) < 0) break;
    if ((ok = st.current_count > 0)) break;
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

}  // namespace

Result<LatencyFloor> raw_dds_pingpong(const DdsSettings& settings, int rounds) {
  if (rounds <= 0)
    return node::fail(Errc::invalid_argument, "raw_dds_pingpong: rounds must be > 0");
  if (auto ok = dds_domain::acquire(settings.domain, settings.config); !ok) {
    return node::fail(ok.error().code, "raw_dds_pingpong: " + ok.error().message);
  }
  DdsPair pair{settings.domain};
  pair.a = dds_create_participant(settings.domain, nullptr, nullptr);
  pair.b = dds_create_participant(settings.domain, nullptr, nullptr);
  if (pair.a < 0 || pair.b < 0) {
    return node::fail(Errc::io, "raw_dds_pingpong: participant: " +
                                    dds_domain::retcode(pair.a < 0 ? pair.a : pair.b));
  }
  const std::string suffix = unique_suffix();
  const std::string ping = "tahvel_floor_ping_" + suffix, pong = "tahvel_floor_pong_" + suffix;
  dds_entity_t ping_w = make_endpoint(pair.a, ping, true),
               pong_r = make_endpoint(pair.a, pong, false);
  dds_entity_t ping_r = make_endpoint(pair.b, ping, false),
               pong_w = make_endpoint(pair.b, pong, true);
  for (dds_entity_t e : {ping_w, pong_r, ping_r, pong_w}) {
    if (e < 0) return node::fail(Errc::io, "raw_dds_pingpong: endpoint: " + dds_domain::retcode(e));
  }
  if (!matched(pair.a, ping_w) || !matched(pair.b, pong_w)) {
    return node::fail(Errc::timeout,
                      "raw_dds_pingpong: ping and pong endpoints did not match within 5 s");
  }
  dds_entity_t ws_a = dds_create_waitset(pair.a), ws_b = dds_create_waitset(pair.b);
  dds_waitset_attach(ws_a, dds_create_readcondition(pong_r, DDS_ANY_STATE), 0);
  dds_waitset_attach(ws_b, dds_create_readcondition(ping_r, DDS_ANY_STATE), 0);
  dds_entity_t wake = dds_create_guardcondition(pair.b);
  dds_waitset_attach(ws_b, wake, 0);

  std::atomic<bool> stop{false};
  std::thread echoer([&] {
    while (!stop.load()) {
      tahvel_Ping msg{};
      void* sample = &msg;
      dds_sample_info_t info;
      dds_return_t n = dds_take(ping_r, &sample, &info, 1, 1);
      if (n == 1 && info.valid_data) dds_write(pong_w, &msg);
      if (n == 0) dds_waitset_wait(ws_b, nullptr, 0, DDS_SECS(1));
      if (n < 0) break;
    }
  });
  const int warmup = warmup_of(rounds);
  std::vector<double> samples;
  samples.reserve(static_cast<std::size_t>(rounds));
  bool lost = false;
  for (int64_t seq = 0; static_cast<int>(samples.size()) < rounds && !lost; ++seq) {
    tahvel_Ping msg{seq}, answer{-1};
    const auto t0 = clock::now();
    const auto deadline = t0 + std::chrono::seconds(5);
    if (dds_write(ping_w, &msg) < 0) lost = true;
    while (!lost && answer.seq != seq) {
      if (!take_one(pong_r, ws_a, deadline, &answer)) lost = true;
    }
    if (!lost && seq >= warmup) samples.push_back(micros(clock::now() - t0) / 2);
  }
  stop = true;
  dds_set_guardcondition(wake, true);
  echoer.join();
  if (lost) return node::fail(Errc::timeout, "raw_dds_pingpong: no pong within 5 s");
  return summarise(std::move(samples));
}

}  // namespace tahvel::federation
