// Pattern matching over one transaction (read-only snapshot or the write path's own).
// A pattern with a bound position walks the index of the bound term with the fewest records
// (idx_s, idx_p or idx_o, each term id -> record ids ascending); a pattern with none bound
// scans the records table. A pattern with a time range reads the items of that range from the
// time index (by_time) instead, when they are fewer than that walk would read. Other positions
// and metadata filters are checked per record.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <unordered_map>
#include <vector>

#include "dictionary.h"
#include "rows.h"
#include "tahvel/node/node.h"

namespace tahvel::node::detail {

class Query {
 public:
  Query(MDB_txn* txn, const Env& env) : txn_(txn), env_(env), terms_(txn, env) {}

  // Calls `visit(id, row)` for each matching record in ascending id order, until it returns
  // false.
  Result<void> for_each(const Pattern& pattern,
                        const std::function<bool(std::uint64_t, const RecordRow&)>& visit);

  // Ids of the records matching any of `patterns`, which all give s, p and o and share the
  // subject and every metadata filter (the removals of Agent::replace, grouped). An id may come
  // twice.
  Result<std::vector<std::uint64_t>> collect_exact(std::span<const Pattern* const> patterns);

  // Ids of the matches and, with cascade, their sub-trees (ListOptions semantics).
  Result<std::vector<std::uint64_t>> collect(const Pattern& pattern, const ListOptions& options);

  // A record with its terms and metadata decoded.
  Result<Record> materialize(std::uint64_t id, const RecordRow& row);
  Result<std::optional<Record>> record(std::uint64_t id);

  TermReader& terms() { return terms_; }

 private:
  struct Bound {
    bool empty = false;  // a bound term the store has never seen: nothing can match
    std::uint64_t s = 0, p = 0, o = 0, context = 0;
    bool has_context = false;
  };
  Result<Bound> resolve(const Pattern& pattern);
  // How many records the index lists for `term` (0 when none).
  Result<std::size_t> index_count(MDB_dbi index, std::uint64_t term);
  Result<bool> metadata_matches(const Pattern& pattern, const Bound& bound, const RecordRow& row);
  // The ids, ascending, of the items whose asserted_at is where a match of the pattern's time
  // range may be: in [since - the longest span, until). nullopt when there are more than `most`.
  Result<std::optional<std::vector<std::uint64_t>>> items_in_range(const Pattern& pattern, std::size_t most);
  Result<const ItemRow*> item(std::uint64_t id);
  // Whether the record subject `subject` (a term id) is `ancestor` or an IRI under it.
  Result<bool> subject_under(const std::string& ancestor, std::uint64_t subject);
  // Adds the records below `object`, `depth` levels deep. `reach` holds, per record already
  // taken, how many levels below its object were walked: a record met again on a shorter path
  // (more levels left) is walked again, not passed over, or what lies deeper below it was lost.
  Result<void> cascade_from(std::uint64_t object, unsigned depth, std::vector<std::uint64_t>& out,
                            std::unordered_map<std::uint64_t, unsigned>& reach, std::size_t limit);

  MDB_txn* txn_;
  const Env& env_;
  TermReader terms_;
  std::uint64_t cached_item_id_ = 0;
  ItemRow cached_item_;
  std::unordered_map<std::uint64_t, bool> source_under_;
  static constexpr std::size_t kSubjectsKept = 4096;
  std::unordered_map<std::uint64_t, bool> subject_under_;  // Pattern::under, by subject id
};

}  // namespace tahvel::node::detail
