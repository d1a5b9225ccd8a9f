#include "check.h"

#include <algorithm>
#include <cstring>
#include <functional>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "dictionary.h"
#include "rows.h"

namespace tahvel::node::detail {

namespace {

// One table's walk: a cursor, closed at the end, and LMDB's refusals turned into problems.
class Walk {
 public:
  Walk(MDB_txn* txn, MDB_dbi dbi) { rc_ = mdb_cursor_open(txn, dbi, &cursor_); }
  ~Walk() {
    if (cursor_) mdb_cursor_close(cursor_);
  }
  Walk(const Walk&) = delete;
  Walk& operator=(const Walk&) = delete;

  // The next entry (every duplicate of a key in turn); false at the end or when LMDB refuses.
  bool next(std::uint64_t& key, MDB_val& value) {
    if (rc_ != 0) return false;
    MDB_val k;
    rc_ = mdb_cursor_get(cursor_, &k, &value, started_ ? MDB_NEXT : MDB_FIRST);
    started_ = true;
    if (rc_ != 0) return false;
    if (k.mv_size != sizeof key) {
      rc_ = MDB_CORRUPTED;
      return false;
    }
    std::memcpy(&key, k.mv_data, sizeof key);
    read_any_ = true;
    return true;
  }
  bool read_any() const { return read_any_; }
  // Why the walk ended early; empty when it reached the end.
  std::string failure() const {
    if (rc_ == 0 || rc_ == MDB_NOTFOUND) return {};
    return lmdb_error(rc_, "reading on").message;
  }

 private:
  MDB_cursor* cursor_ = nullptr;
  int rc_ = 0;
  bool started_ = false, read_any_ = false;
};

std::uint64_t u64(const MDB_val& v) {
  std::uint64_t x = 0;
  if (v.mv_size == sizeof x) std::memcpy(&x, v.mv_data, sizeof x);
  return x;
}

class Checker {
 public:
  Checker(Env& env, MDB_txn* txn, std::size_t max_problems, const std::function<void(std::string_view)>& found)
      : env_(env), txn_(txn), max_(max_problems), found_(found) {}

  void problem(std::string what) {
    // After LMDB refuses a page (damaged, MDB_CORRUPTED), the read transaction refuses every
    // later read (MDB_BAD_TXN): one bad page of idx_s was reported as eleven damaged tables.
    if (broken_) {
      ++unsaid_;
      return;
    }
    keep(std::move(what));
    MDB_val k = val(std::string_view("counters")), v;
    broken_ = mdb_get(txn_, env_.main, &k, &v) == MDB_BAD_TXN;
  }
  void ended(const Walk& walk, std::string_view table, std::uint64_t after) {
    if (auto why = walk.failure(); !why.empty()) {
      cut_.insert(std::string(table));
      problem(std::string(table) + ": the walk stops " + (walk.read_any() ? "after key " + std::to_string(after) : "at its start") +
              ": " + why);
    }
  }
  // After a step whose read LMDB refused: the next steps read on a new read transaction, and
  // what the refused one would have said of `step` is counted as its consequence, not said.
  // False when no new read can begin (the steps after would say nothing true).
  bool read_anew(std::string_view step) {
    if (!broken_) return true;
    cut_.insert(std::string(step));
    mdb_txn_reset(txn_);
    const int rc = mdb_txn_renew(txn_);
    broken_ = false;
    const std::size_t unsaid = std::exchange(unsaid_, 0);
    if (rc != 0) {
      problem("the store cannot be read again after the problem above: " + lmdb_error(rc, "beginning a read").message);
      return false;
    }
    keep(std::string(step) + ": LMDB refused the rest of this read after the problem above" +
         (unsaid ? " (" + std::to_string(unsaid) + " later finding(s) of it left unsaid)" : "") + "; the tables after " +
         std::string(step) + " are read anew");
    return true;
  }
  void keep(std::string what) {
    ++report.problems_found;
    if (report.problems.size() >= max_) return;
    if (found_) found_(what);
    report.problems.push_back(std::move(what));
  }

  bool has_term(std::uint64_t id) const {
    return id == 0 || is_inline(id) || std::binary_search(term_ids_.begin(), term_ids_.end(), id);
  }
  void need_term(std::uint64_t id, const std::string& whose) {
    // A terms walk cut short (a damaged page) saw not all terms; of two tables (terms,
    // long_terms), the unseen ids may be anywhere.
    if (cut_.count("terms") || cut_.count("long_terms")) return;
    if (!has_term(id)) problem(whose + " names term " + std::to_string(id) + ", which is not in the dictionary");
  }

  void terms_of(MDB_dbi table, const char* name) {
    Walk walk(txn_, table);
    TermReader reader(txn_, env_);
    std::uint64_t id = 0;
    MDB_val v;
    while (walk.next(id, v)) {
      term_ids_.push_back(id);
      ++report.terms;
      auto term = reader.get(id, false, false);
      if (!term) {
        problem("term " + std::to_string(id) + ": " + term.error().message);
        continue;
      }
      // LMDB checksums no page: a page overwritten in the middle of a long literal still
      // decodes. What the store never writes (ill-formed UTF-8), and text that no longer hashes
      // to its own entry, is a damaged term, which a dump would copy out as it is.
      bool named = false;  // one problem per term
      for (const std::string* part : {&term->value, &term->datatype, &term->language})
        if (const std::size_t at = ill_formed_utf8_at(*part); !named && at != std::string::npos) {
          problem("term " + std::to_string(id) + ": not UTF-8 at byte " + std::to_string(at) + " of its " +
                  (part == &term->value ? "text" : part == &term->datatype ? "datatype" : "language tag") + " (damaged)");
          named = true;
        }
      if (auto found = find_term(txn_, env_, *term); !named && found && *found != id)
        problem("term " + std::to_string(id) + ": its text is not found under its own hash (damaged, or its hash entry is)");
    }
    ended(walk, name, id);
  }

  void terms() {
    // Short terms, then long ones (format 4): the ids are sorted after, for has_term.
    for (const MDB_dbi table : {env_.terms, env_.long_terms})
      if (table != 0) terms_of(table, table == env_.terms ? "terms" : "long_terms");
    std::sort(term_ids_.begin(), term_ids_.end());
    MDB_val v;
    Walk hashes(txn_, env_.term_hash);
    std::uint64_t hash = 0;
    while (hashes.next(hash, v)) {
      if (!has_term(u64(v)))
        problem("term_hash: hash " + std::to_string(hash) + " names term " + std::to_string(u64(v)) +
                ", which is not in the dictionary");
    }
    ended(hashes, "term_hash", hash);
  }

  // Records in id order; an item's records are a run of ids from the item's own, so the
  // records of each item are counted as one run.
  void records() {
    Walk walk(txn_, env_.records);
    Cursor index[3];
    const MDB_dbi dbis[3] = {env_.idx_s, env_.idx_p, env_.idx_o};
    const char* names[3] = {"subject", "predicate", "object"};
    for (int i = 0; i < 3; ++i)
      if (int rc = mdb_cursor_open(txn_, dbis[i], &index[i].c); rc != 0)
        problem(std::string("the ") + names[i] + " index cannot be read: " + lmdb_error(rc, "opening").message);
    std::uint64_t id = 0;
    MDB_val v;
    std::uint64_t item = 0;
    std::optional<ItemRow> item_row;
    while (walk.next(id, v)) {
      ++report.records;
      const std::string whose = "record " + std::to_string(id);
      RecordRow row;
      if (!decode_record(id, view(v), row)) {
        problem(whose + ": its row does not decode");
        continue;
      }
      need_term(row.s, whose + " (subject)");
      need_term(row.p, whose + " (predicate)");
      need_term(row.o, whose + " (object)");
      const std::uint64_t terms[3] = {row.s, row.p, row.o};
      for (int i = 0; i < 3 && !broken_; ++i) {
        MDB_val k = val(terms[i]), d = val(id);
        const int rc = index[i].c ? mdb_cursor_get(index[i].c, &k, &d, MDB_GET_BOTH) : 0;
        if (rc == MDB_NOTFOUND) problem(whose + " is not in the " + names[i] + " index");
        else if (rc != 0)
          problem(std::string("the ") + names[i] + " index cannot be read at " + whose + ": " + lmdb_error(rc, "looking it up").message);
      }
      if (broken_) break;
      if (runs_.empty() || runs_.back().first != row.item) {
        runs_.emplace_back(row.item, 0);
        item = row.item;
        auto got = get_item(txn_, env_, item);
        item_row = got ? *got : std::nullopt;
        if (!got) problem(whose + ": its item " + std::to_string(item) + ": " + got.error().message);
        else if (!*got) problem(whose + " names item " + std::to_string(item) + ", which is not in the store");
      }
      ++runs_.back().second;
      if (item_row && (id < item || id - item >= item_row->count))
        problem(whose + " lies outside its item " + std::to_string(item) + " (records " + std::to_string(item) + " to " +
                std::to_string(item + item_row->count - 1) + ")");
    }
    ended(walk, "records", id);
    max_record_ = id;
  }

  void items() {
    Walk walk(txn_, env_.items);
    Cursor times, outbox;
    if (int rc = env_.by_time ? mdb_cursor_open(txn_, env_.by_time, &times.c) : 0; rc != 0)
      problem("the time index cannot be read: " + lmdb_error(rc, "opening").message);
    if (int rc = mdb_cursor_open(txn_, env_.outbox, &outbox.c); rc != 0)
      problem("the output buffers cannot be read: " + lmdb_error(rc, "opening").message);
    std::sort(runs_.begin(), runs_.end());
    auto run = runs_.begin();
    std::uint64_t id = 0;
    MDB_val v;
    while (walk.next(id, v)) {
      ++report.items;
      const std::string whose = "item " + std::to_string(id);
      ItemRow row;
      if (!decode_item(view(v), row)) {
        problem(whose + ": its row does not decode (truncated, or written by a later build)");
        continue;
      }
      need_term(row.source, whose + " (source)");
      need_term(row.context, whose + " (context)");
      need_term(row.writer, whose + " (writer)");
      while (run != runs_.end() && run->first < id) ++run;
      const std::uint64_t found = run != runs_.end() && run->first == id ? run->second : 0;
      // The records walk cut short (a damaged page) saw none of the later items' records.
      const bool records_seen = !cut_.count("records") || (!runs_.empty() && id < runs_.back().first);
      if (records_seen && found != row.live)
        problem(whose + " counts " + std::to_string(row.live) + " live records; the records table holds " +
                std::to_string(found));
      if (times.c) {
        const std::uint64_t at = time_key(row.asserted_at);
        MDB_val k = val(at), d = val(id);
        if (mdb_cursor_get(times.c, &k, &d, MDB_GET_BOTH) != 0) problem(whose + " is not in the time index");
      }
      // Every item is in its writer's output buffer until it goes (write.cpp, rows.cpp).
      if (outbox.c) {
        const std::uint64_t writer = row.output_buffer();
        MDB_val k = val(writer), d = val(id);
        if (mdb_cursor_get(outbox.c, &k, &d, MDB_GET_BOTH) != 0) problem(whose + " is not in its writer's output buffer");
      }
      max_span_ = std::max(max_span_, row.span);
    }
    ended(walk, "items", id);
    max_item_ = id;
  }

  // Walks a table of id values (an index, the time index, a buffer: key -> ids), counting each
  // entry in `count` and handing it to `entry(key, id)`.
  template <class Entry>
  void each_id(MDB_dbi dbi, std::string_view table, std::uint64_t& count, Entry entry) {
    Walk walk(txn_, dbi);
    std::uint64_t key = 0;
    MDB_val v;
    while (walk.next(key, v)) {
      ++count;
      entry(key, u64(v));
    }
    ended(walk, table, key);
  }

  // Every index entry names a record that has the entry's term in that position.
  void index(MDB_dbi dbi, const char* table, int position) {
    each_id(dbi, table, report.index_entries, [&](std::uint64_t key, std::uint64_t id) {
      const std::string whose = std::string(table) + ": term " + std::to_string(key);
      auto row = get_record(txn_, env_, id);
      if (!row) problem(whose + " -> record " + std::to_string(id) + ": " + row.error().message);
      else if (!*row) problem(whose + " names record " + std::to_string(id) + ", which is not in the store");
      else if (const std::uint64_t terms[3] = {(*row)->s, (*row)->p, (*row)->o}; terms[position] != key)
        problem(whose + " names record " + std::to_string(id) + ", whose term there is " + std::to_string(terms[position]));
    });
  }

  void time_index() {
    if (!env_.by_time) return;
    each_id(env_.by_time, "by_time", report.time_entries, [&](std::uint64_t key, std::uint64_t id) {
      auto row = get_item(txn_, env_, id);
      if (!row) problem("by_time: item " + std::to_string(id) + ": " + row.error().message);
      else if (!*row) problem("by_time: an entry names item " + std::to_string(id) + ", which is not in the store");
      else if (time_key((*row)->asserted_at) != key)
        problem("by_time: item " + std::to_string(id) + " is listed at another time than it was asserted at");
    });
  }

  // An input buffer entry names an item or a removal notice that is there (both leave the
  // buffers when they go); an output buffer entry names an item whose output buffer it is.
  void buffers(MDB_dbi dbi, const char* table, bool output) {
    each_id(dbi, table, report.buffer_entries, [&](std::uint64_t key, std::uint64_t id) {
      const std::string whose = std::string(table) + ": agent term " + std::to_string(key) + " holds " + std::to_string(id);
      auto item = get_item(txn_, env_, id);
      if (!item) {
        problem(whose + ": " + item.error().message);
        return;
      }
      if (output) {
        if (!*item) problem(whose + ", which is not an item in the store");
        else if ((*item)->output_buffer() != key) problem(whose + ", an item of another output buffer");
        return;
      }
      if (*item) return;
      auto notice = get_notice(txn_, env_, id);
      if (!notice) problem(whose + ": " + notice.error().message);
      else if (!*notice) problem(whose + ", which is neither an item nor a removal notice in the store");
    });
  }

  void counters() {
    auto c = load_counters(txn_, env_.main);
    if (!c) {
      problem("counters: " + c.error().message);
      return;
    }
    auto compare = [&](const char* what, std::uint64_t counted, std::uint64_t kept) {
      if (counted != kept)
        problem(std::string("counters: ") + what + " " + std::to_string(kept) + ", the tables hold " + std::to_string(counted));
    };
    // A table whose walk was cut short has counted less than it holds: no finding of its own.
    if (!cut_.count("records")) compare("records", report.records, c->records);
    if (!cut_.count("items")) compare("items", report.items, c->items);
    if (!cut_.count("terms") && !cut_.count("long_terms")) compare("terms", report.terms, c->terms);
    // Ids only grow: a counter at or below an id in use would hand it out again.
    if (c->next_seq <= std::max(max_record_, max_item_))
      problem("counters: next id " + std::to_string(c->next_seq) + ", but id " + std::to_string(std::max(max_record_, max_item_)) +
              " is in use");
    if (!term_ids_.empty() && c->next_term <= term_ids_.back())
      problem("counters: next term id " + std::to_string(c->next_term) + ", but term " + std::to_string(term_ids_.back()) +
              " is in use");
    // A time range is looked for from max_span before it: a longer span would be missed.
    if (static_cast<std::uint64_t>(std::max<std::int64_t>(max_span_, 0)) > c->max_span)
      problem("counters: the longest span is kept as " + std::to_string(c->max_span) + " ns, but an item spans " +
              std::to_string(max_span_) + " ns (time ranges would miss it)");
  }

  CheckReport report;

 private:
  Env& env_;
  MDB_txn* txn_;
  std::size_t max_;
  const std::function<void(std::string_view)>& found_;
  bool broken_ = false;       // LMDB refused this read: later reads of it fail as MDB_BAD_TXN
  std::size_t unsaid_ = 0;    // findings while broken_, consequences of the refusal
  std::set<std::string> cut_;  // tables whose walk did not reach the end
  std::vector<std::uint64_t> term_ids_;                          // ascending, as the table holds them
  std::vector<std::pair<std::uint64_t, std::uint64_t>> runs_;  // item -> records seen
  std::uint64_t max_record_ = 0, max_item_ = 0;                 // the greatest ids in use
  std::int64_t max_span_ = 0;                                   // the longest item span
};

}  // namespace

Result<CheckReport> check_store(Env& env, MDB_txn* txn, std::size_t max_problems,
                                const std::function<void(std::string_view table)>& progress,
                                const std::function<void(std::string_view problem)>& found) {
  Checker check(env, txn, max_problems, found);
  auto step = [&](std::string_view table) {
    if (progress) progress(table);
  };
  const std::pair<std::string_view, std::function<void()>> steps[] = {
      {"terms", [&] { check.terms(); }},
      {"records", [&] { check.records(); }},
      {"items", [&] { check.items(); }},
      {"idx_s", [&] { check.index(env.idx_s, "idx_s", 0); }},
      {"idx_p", [&] { check.index(env.idx_p, "idx_p", 1); }},
      {"idx_o", [&] { check.index(env.idx_o, "idx_o", 2); }},
      {"by_time", [&] { check.time_index(); }},
      {"inbox", [&] { check.buffers(env.inbox, "inbox", false); }},
      {"outbox", [&] { check.buffers(env.outbox, "outbox", true); }},
      {"counters", [&] { check.counters(); }},
  };
  for (const auto& [table, run] : steps) {
    step(table);
    run();
    if (!check.read_anew(table)) break;
  }
  return std::move(check.report);
}

}  // namespace tahvel::node::detail
