// `tahvel bench store`: Tahvel's store against its peers, in one run, on the same records
// (bench_mix.h). What each figure means and how it is taken:
//   item writes      one Agent::store() per item (its own transaction) into a fresh fast-mode
//                    store; SQLite: BEGIN; INSERT per triple; COMMIT with prepared statements.
//                    Single-triple items are the triples of the mix one by one; 10-triple items
//                    are whole observations. The durable-mode run and SQLite's defaults stop at
//                    a time cap (they fsync every commit), so they report fewer items.
//   bulk load        --records triples as observations, --bulk-items observations (x10 triples)
//                    per Agent::store_all() call and per SQLite transaction; Sord: sord_add of
//                    each triple. Only the write calls are timed, never the generator.
//   queries          over the bulk-loaded records: a bound subject (one observation: 10 matches)
//                    and a bound predicate limited to its first 100 matches (ListOptions.limit;
//                    SQLite LIMIT 100; Sord stops its iterator at 100), each query with a fresh
//                    snapshot (SQLite: its own read transaction), results copied out. Then
//                    time ranges of 100 observations (1,000 records; Pattern::since/until),
//                    up to 1,000 of them; SQLite: WHERE asserted_at in the range, with an index
//                    on asserted_at made after the load (not in its write figures). Sord has no
//                    time.
//   wake             Agent::store() here to Agent::take() returning in a forked subscriber
//                    (bench_tahvel.h); the floor is a UNIX socketpair ping-pong (RTT / 2),
//                    back to back and with the same pause as the wake probes.
//   bytes/triple     Stats.used_bytes / Stats.records after the bulk load; SQLite: pages in use.
// Nothing here asserts on time: the bench prints, the reader judges.
#include <algorithm>
#include <charconv>
#include <cstdio>
#include <exception>
#include <iostream>
#include <optional>
#include <stdexcept>

#include "bench.h"
#include "bench_measure.h"
#include "bench_mix.h"
#include "bench_peers.h"
#include "bench_report.h"
#include "bench_tahvel.h"

namespace tahvel::cli {
namespace bench {
namespace {

using namespace std::chrono_literals;

struct Config {
  bool json = false;
  std::uint64_t records = 1'000'000;
  std::size_t single_items = 20'000;
  std::size_t item_rounds = 5;     // single-triple rounds, Tahvel and SQLite alternating
  std::size_t item10_items = 5'000;
  std::size_t slow_items = 2'000;  // SQLite defaults and Tahvel durable
  Clock::duration slow_cap = 4s;   // ... stop there after this long
  std::size_t bulk_items = 100;    // observations per bulk transaction
  std::size_t queries = 10'000;
  std::size_t query_limit = 100;
  std::size_t wake_samples = 2'000;
  std::chrono::microseconds wake_pause{500};
  std::size_t round_trips = 20'000;
  std::filesystem::path dir;
};

const char* kUsage =
    "usage: tahvel bench store [--json] [--quick] [--records N] [--bulk-items N] [--dir PATH] [--wake-pause-us N]\n"
    "  --json          print one JSON object instead of the table\n"
    "  --quick         a small run (seconds), for smoke tests\n"
    "  --records N     triples bulk-loaded and queried (default 1000000)\n"
    "  --bulk-items N  observations (10 triples each) per bulk transaction (default 100)\n"
    "  --dir PATH      where the scratch stores go (default: the temporary directory)\n"
    "  --wake-pause-us N  pause before each wake probe and paused socket ping (default 500)\n";

void make_quick(Config& c) {
  c.records = 20'000;
  c.single_items = 2'000;
  c.item_rounds = 1;
  c.item10_items = 500;
  c.slow_items = 200;
  c.slow_cap = 1s;
  c.queries = 1'000;
  c.wake_samples = 200;
  c.round_trips = 2'000;
}

std::uint64_t parse_count(const std::string& flag, const std::string& text) {
  std::uint64_t n = 0;
  auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), n);
  if (ec != std::errc() || end != text.data() + text.size() || n == 0) {
    throw std::invalid_argument(flag + " wants a positive number, not '" + text + "'");
  }
  return n;
}

// Returns nullopt after printing the usage for --help.
std::optional<Config> parse(const std::vector<std::string>& args) {
  Config c;
  std::optional<std::uint64_t> records, bulk_items;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&]() -> const std::string& {
      if (i + 1 >= args.size()) throw std::invalid_argument(a + " wants a value");
      return args[++i];
    };
    if (a == "--json")
      c.json = true;
    else if (a == "--quick")
      make_quick(c);
    else if (a == "--records")
      records = parse_count(a, value());
    else if (a == "--bulk-items")
      bulk_items = parse_count(a, value());
    else if (a == "--dir")
      c.dir = value();
    else if (a == "--wake-pause-us")
      c.wake_pause = std::chrono::microseconds(parse_count(a, value()));
    else if (a == "--help" || a == "-h")
      return std::nullopt;
    else if (i == 0 && a == "store")
      continue;  // tolerate `store` left in by a dispatcher
    else
      throw std::invalid_argument("unknown argument '" + a + "'\n" + kUsage);
  }
  if (records) c.records = *records;
  if (bulk_items) c.bulk_items = *bulk_items;
  c.records =
      std::max<std::uint64_t>(c.records / kTriplesPerObservation, 1) * kTriplesPerObservation;
  return c;
}

[[noreturn]] void raise(const node::Error& e) { throw std::runtime_error(e.message); }

template <class T>
T must(node::Result<T> r) {
  if (!r) raise(r.error());
  return std::move(*r);
}

class Progress {
 public:
  explicit Progress(bool quiet) : quiet_(quiet) {}
  void operator()(const std::string& step) const {
    if (!quiet_) std::cerr << "bench: " << step << "\n";
  }

 private:
  bool quiet_;
};

// Calls `store(item)` per item, timed one by one, until all are written or `cap` has passed.
template <class Store>
Rate store_each(const std::vector<node::Item>& items, Clock::duration cap, std::vector<double>* us,
                Store&& store) {
  Rate rate;
  const auto start = Clock::now();
  for (const node::Item& item : items) {
    auto t0 = Clock::now();
    store(item);
    auto dt = Clock::now() - t0;
    rate.elapsed += dt;
    rate.items += 1;
    rate.triples += item.triples.size();
    if (us) us->push_back(micros(dt));
    if (Clock::now() - start > cap) break;
  }
  return rate;
}

// Bulk-loads `records` triples: batches of observations, generated untimed, written by `load`.
template <class Load>
Rate load_records(const Config& c, Load&& load) {
  Rate rate;
  const std::uint64_t total = c.records / kTriplesPerObservation;
  for (std::uint64_t first = 0; first < total; first += c.bulk_items) {
    std::vector<node::Item> batch = observations(
        first, static_cast<std::size_t>(std::min<std::uint64_t>(c.bulk_items, total - first)));
    auto t0 = Clock::now();
    load(batch);
    rate.elapsed += Clock::now() - t0;
    rate.items += batch.size();
    rate.triples += batch.size() * kTriplesPerObservation;
  }
  return rate;
}

// The same random queries for every system.
struct QueryPlan {
  std::vector<std::string> subjects, predicates;
  std::size_t limit = 100;
  // Time ranges of kRangeObservations observations each (observation_time): [since, until).
  std::vector<std::pair<std::int64_t, std::int64_t>> ranges;
};

constexpr std::uint64_t kRangeObservations = 100;

QueryPlan make_plan(const Config& c) {
  QueryPlan plan;
  plan.limit = c.query_limit;
  Rng rng(0x5eed);
  const auto& preds = mix_predicates();
  for (std::size_t i = 0; i < c.queries; ++i) {
    plan.subjects.push_back(observation_iri(rng.below(c.records / kTriplesPerObservation)));
    plan.predicates.push_back(preds[rng.below(preds.size())]);
  }
  const std::uint64_t total = c.records / kTriplesPerObservation;
  // At most 1,000: each returns a thousand records.
  for (std::size_t i = 0; i < std::min<std::size_t>(c.queries, 1'000) && total > kRangeObservations; ++i) {
    const std::uint64_t first = rng.below(total - kRangeObservations);
    plan.ranges.emplace_back(observation_time(first), observation_time(first + kRangeObservations));
  }
  return plan;
}

void set_percentiles(Figures& f, const std::string& prefix, const Percentiles& p) {
  f.set(prefix + "_p50_us", p.p50_us);
  f.set(prefix + "_p99_us", p.p99_us);
}

// Runs both query sets through `list_s(iri)` and `list_p(iri, limit)`, which return row counts.
template <class ListS, class ListP>
void time_queries(Figures& f, const std::string& prefix, const QueryPlan& plan, ListS&& list_s,
                  ListP&& list_p) {
  std::uint64_t rows_s = 0, rows_p = 0;
  set_percentiles(f, prefix + "query_s", time_each(plan.subjects, rows_s, list_s));
  set_percentiles(f, prefix + "query_p", time_each(plan.predicates, rows_p, [&](const auto& p) {
                    return list_p(p, plan.limit);
                  }));
  f.set(prefix + "query_s_rows", static_cast<double>(rows_s));
  f.set(prefix + "query_p_rows", static_cast<double>(rows_p));
}

// Runs the time ranges through `list_range(since, until)`, which returns a row count.
template <class ListRange>
void time_ranges(Figures& f, const std::string& prefix, const QueryPlan& plan, ListRange&& list_range) {
  std::uint64_t rows = 0;
  set_percentiles(f, prefix + "query_range", time_each(plan.ranges, rows, [&](const auto& range) {
                    return list_range(range.first, range.second);
                  }));
  f.set(prefix + "query_range_rows", static_cast<double>(rows));
}

// ---------------------------------------------------------------------------------------------
// Phases

void measure_latency(const Config& c, const ScratchDir& tmp, Figures& f, const Progress& say) {
  // Back to back, both processes on one CPU: the conditions of the socket floor (the
  // scheduler keeps an unpinned ping-pong pair on one CPU most of the time, and pinning makes
  // the figure repeatable). Then the same across two CPUs, and paused, unpinned.
  const Placement one = one_cpu();
  say("UNIX socket ping-pong, one CPU");
  set_percentiles(f, "unix_socket", unix_socket_one_way(c.round_trips, 0us, one));
  say("store-to-wake across processes, back to back, one CPU");
  WakeFigures wake = must(tahvel_wake(tmp.sub("wake"), c.wake_samples, 0us, one));
  set_percentiles(f, "wake", wake.wake);
  set_percentiles(f, "wake_store_call", wake.store_call);
  set_percentiles(f, "wake_after_store", wake.after_store);
  f.set("wake_samples", static_cast<double>(wake.wake.samples));
  if (std::optional<Placement> two = two_cpus()) {
    say("UNIX socket ping-pong and store-to-wake, two CPUs");
    set_percentiles(f, "unix_socket_two_cpus", unix_socket_one_way(c.round_trips, 0us, *two));
    WakeFigures across = must(tahvel_wake(tmp.sub("wake_two"), c.wake_samples, 0us, *two));
    set_percentiles(f, "wake_two_cpus", across.wake);
  }
  say("UNIX socket, futex and store-to-wake, paused");
  set_percentiles(f, "unix_socket_paused", unix_socket_one_way(c.wake_samples, c.wake_pause));
  set_percentiles(f, "futex_wake", futex_wake(c.wake_samples, c.wake_pause));
  WakeFigures paused = must(tahvel_wake(tmp.sub("wake_paused"), c.wake_samples, c.wake_pause));
  set_percentiles(f, "wake_paused", paused.wake);
  set_percentiles(f, "wake_paused_store_call", paused.store_call);
  set_percentiles(f, "wake_paused_after_store", paused.after_store);
}

double median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  return values.empty() ? 0 : values[values.size() / 2];
}

Rate tahvel_items(const std::filesystem::path& dir, node::Durability durability,
                  const std::vector<node::Item>& items, Clock::duration cap,
                  std::vector<double>* us) {
  node::Node store = must(tahvel_init(dir, durability));
  node::Agent agent = must(store.agent("bench"));
  return store_each(items, cap, us, [&](const node::Item& item) { must(agent.store(item)); });
}

Rate sqlite_items(const std::filesystem::path& file, SqliteMode mode,
                  const std::vector<node::Item>& items, Clock::duration cap,
                  std::vector<double>* us) {
  SqlitePeer db(file, mode);
  return store_each(items, cap, us, [&](const node::Item& item) { db.store(item); });
}

void measure_items(const Config& c, const ScratchDir& tmp, Figures& f, const Progress& say) {
  const auto singles = single_triples(0, c.single_items);
  const auto slow = single_triples(0, c.slow_items);
  const auto tens = observations(0, c.item10_items);
  const auto no_cap = Clock::duration::max() / 2;
  // Rounds alternate between the two systems, each in a fresh store, and the median round
  // counts: a burst of noise on this shared machine then hits one round, not one system.
  std::vector<double> us, sqlite_us, rates, sqlite_rates;
  say("single-triple items: Tahvel fast and SQLite WAL sync=OFF, alternating rounds");
  for (std::size_t round = 0; round < c.item_rounds; ++round) {
    const std::string n = std::to_string(round);
    rates.push_back(
        tahvel_items(tmp.sub("items1-" + n), node::Durability::fast, singles, no_cap, &us).items_per_s());
    sqlite_rates.push_back(sqlite_items(tmp.sub("items1-" + n + ".sqlite"), SqliteMode::wal_sync_off,
                                        singles, no_cap, &sqlite_us)
                               .items_per_s());
  }
  f.set("item_writes_per_s", median(rates));
  f.set("sqlite_item_writes_per_s", median(sqlite_rates));
  f.set("item_rounds", static_cast<double>(c.item_rounds));
  set_percentiles(f, "item_store", percentiles(std::move(us)));
  set_percentiles(f, "sqlite_item_store", percentiles(std::move(sqlite_us)));
  say("single-triple items: SQLite defaults, Tahvel durable (time-capped)");
  Rate sd =
      sqlite_items(tmp.sub("default.sqlite"), SqliteMode::defaults, slow, c.slow_cap, nullptr);
  f.set("sqlite_default_item_writes_per_s", sd.items_per_s());
  f.set("sqlite_default_items", static_cast<double>(sd.items));
  Rate td = tahvel_items(tmp.sub("durable"), node::Durability::durable, slow, c.slow_cap, nullptr);
  f.set("item_durable_writes_per_s", td.items_per_s());
  f.set("item_durable_items", static_cast<double>(td.items));
  say("10-triple items: Tahvel fast, SQLite WAL sync=OFF");
  Rate t10 = tahvel_items(tmp.sub("items10"), node::Durability::fast, tens, no_cap, nullptr);
  f.set("item10_writes_per_s", t10.items_per_s());
  f.set("item10_triples_per_s", t10.triples_per_s());
  Rate s10 =
      sqlite_items(tmp.sub("items10.sqlite"), SqliteMode::wal_sync_off, tens, no_cap, nullptr);
  f.set("sqlite_item10_writes_per_s", s10.items_per_s());
  f.set("sqlite_item10_triples_per_s", s10.triples_per_s());
}

void measure_tahvel_bulk(const Config& c, const ScratchDir& tmp, const QueryPlan& plan, Figures& f,
                         const Progress& say) {
  say("bulk load and queries: Tahvel");
  node::Node store = must(tahvel_init(tmp.sub("bulk"), node::Durability::fast));
  node::Agent agent = must(store.agent("bench"));
  Rate rate =
      load_records(c, [&](const std::vector<node::Item>& batch) { must(agent.store_all(batch)); });
  f.set("bulk_triples_per_s", rate.triples_per_s());
  node::Stats stats = must(store.stats());
  f.set("bytes_per_triple",
        stats.records ? static_cast<double>(stats.used_bytes) / static_cast<double>(stats.records)
                      : 0);
  f.set("store_records", static_cast<double>(stats.records));
  f.set("store_used_bytes", static_cast<double>(stats.used_bytes));
  auto list = [&](const node::Pattern& pattern, std::size_t limit) {
    node::Snapshot snap = must(store.snapshot());
    node::ListOptions options;
    options.limit = limit;
    return must(snap.list(pattern, options)).size();
  };
  node::Pattern by_s, by_p;
  time_queries(
      f, "", plan,
      [&](const std::string& s) {
        by_s.s = node::Term::iri(s);
        return list(by_s, 0);
      },
      [&](const std::string& p, std::size_t limit) {
        by_p.p = node::Term::iri(p);
        return list(by_p, limit);
      });
  time_ranges(f, "", plan, [&](std::int64_t since, std::int64_t until) {
    return list({.since = since, .until = until}, 0);
  });
}

void measure_sord_bulk(const Config& c, const QueryPlan& plan, Figures& f, const Progress& say) {
  say("bulk load and queries: Sord");
  SordPeer sord;
  Rate rate = load_records(c, [&](const std::vector<node::Item>& batch) { sord.add(batch); });
  f.set("sord_bulk_triples_per_s", rate.triples_per_s());
  time_queries(
      f, "sord_", plan, [&](const std::string& s) { return sord.list_subject(s).size(); },
      [&](const std::string& p, std::size_t limit) {
        return sord.list_predicate(p, limit).size();
      });
}

void measure_sqlite_bulk(const Config& c, const ScratchDir& tmp, const QueryPlan& plan, Figures& f,
                         const Progress& say) {
  say("bulk load and queries: SQLite WAL sync=OFF");
  SqlitePeer db(tmp.sub("bulk.sqlite"), SqliteMode::wal_sync_off);
  Rate rate = load_records(c, [&](const std::vector<node::Item>& batch) { db.store_all(batch); });
  f.set("sqlite_bulk_triples_per_s", rate.triples_per_s());
  f.set("sqlite_bytes_per_triple", static_cast<double>(db.used_bytes()) /
                                       static_cast<double>(std::max<std::uint64_t>(db.rows(), 1)));
  time_queries(
      f, "sqlite_", plan, [&](const std::string& s) { return db.list_subject(s).size(); },
      [&](const std::string& p, std::size_t limit) { return db.list_predicate(p, limit).size(); });
  db.index_time();
  time_ranges(f, "sqlite_", plan, [&](std::int64_t since, std::int64_t until) { return db.list_range(since, until).size(); });
}

// The systems must have answered the same queries with the same number of rows.
void check_rows(const Figures& f) {
  if (f.get("query_range_rows") != f.get("sqlite_query_range_rows"))
    std::cerr << "bench: warning: query_range_rows differ: Tahvel " << f.get("query_range_rows") << ", SQLite "
              << f.get("sqlite_query_range_rows") << "\n";
  for (const char* q : {"query_s_rows", "query_p_rows"}) {
    double t = f.get(q), s = f.get(std::string("sqlite_") + q), o = f.get(std::string("sord_") + q);
    if (t != s || t != o) {
      std::cerr << "bench: warning: " << q << " differ: Tahvel " << t << ", SQLite " << s
                << ", Sord " << o << "\n";
    }
  }
}

void set_config(const Config& c, Figures& f) {
  f.set("records", static_cast<double>(c.records));
  f.set("single_items", static_cast<double>(c.single_items));
  f.set("item10_items", static_cast<double>(c.item10_items));
  f.set("bulk_triples_per_transaction", static_cast<double>(c.bulk_items * kTriplesPerObservation));
  f.set("queries", static_cast<double>(c.queries));
  f.set("query_p_limit", static_cast<double>(c.query_limit));
  f.set("wake_pause_us", static_cast<double>(c.wake_pause.count()));
}

void print_setup(const Config& c, const Figures& f) {
  std::printf(
      "tahvel bench store: %llu records (observations of 10 triples), bulk %zu triples per "
      "transaction;\n  items: %zu rounds of %zu single-triple (median), %zu 10-triple; capped runs: SQLite defaults %.0f, "
      "Tahvel durable %.0f items;\n  %zu queries of each kind (bound p: first %zu matches); %zu "
      "wake probes, %lld us apart\n\n",
      static_cast<unsigned long long>(c.records), c.bulk_items * kTriplesPerObservation,
      c.item_rounds, c.single_items, c.item10_items, f.get("sqlite_default_items"), f.get("item_durable_items"),
      c.queries, c.query_limit, c.wake_samples, static_cast<long long>(c.wake_pause.count()));
}

int run(const Config& c) {
  Progress say(c.json);
  Figures f;
  set_config(c, f);
  ScratchDir tmp(c.dir);
  measure_latency(c, tmp, f, say);  // first: forks before this process opens any store
  measure_items(c, tmp, f, say);
  const QueryPlan plan = make_plan(c);
  measure_tahvel_bulk(c, tmp, plan, f, say);
  measure_sord_bulk(c, plan, f, say);
  measure_sqlite_bulk(c, tmp, plan, f, say);
  check_rows(f);
  add_ratios(f);
  if (c.json) {
    print_json(std::cout, f);
  } else {
    print_setup(c, f);
    print_table(std::cout, f);
  }
  return 0;
}

}  // namespace
}  // namespace bench

int bench_store_main(const std::vector<std::string>& args) {
  return parse_and_run_bench("store", args, bench::kUsage, bench::parse, bench::run);
}

}  // namespace tahvel::cli
