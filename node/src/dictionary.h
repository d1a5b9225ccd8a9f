// The term dictionary: each distinct term is stored once and named by a 64-bit id (DESIGN §3).
//
// Ids with the top bit set are inline and have no dictionary entry: renamed blank nodes
// (a per-node counter) and xsd:integer literals in canonical form that fit in 60 bits. They are
// the bulk of new terms in sensor data, so inlining them keeps the dictionary and the bytes per
// triple small. Other terms live in table `terms` (id -> flags + payload) and are found by
// `term_hash` (FNV-1a of the payload -> ids, collisions resolved by comparing payloads).
//
// Payload: kind byte, then for IRIs the IRI; for literals varint(datatype id, 0 for xsd:string
// and language-tagged), language length byte, language, lexical form.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <unordered_map>

#include "env.h"
#include "tahvel/node/term.h"

namespace tahvel::node::detail {

inline constexpr std::uint64_t kInlineBit = 1ull << 63;
inline constexpr std::uint64_t kInlineKindShift = 60;
inline constexpr std::uint64_t kInlineBlank = 0;
inline constexpr std::uint64_t kInlineInteger = 1;
inline constexpr std::uint64_t kInlinePayloadMask = (1ull << 60) - 1;

inline bool is_inline(std::uint64_t id) { return id & kInlineBit; }
inline std::uint64_t inline_blank(std::uint64_t n) {
  return kInlineBit | (kInlineBlank << kInlineKindShift) | (n & kInlinePayloadMask);
}
inline bool is_blank_id(std::uint64_t id) {
  return is_inline(id) && ((id >> kInlineKindShift) & 7) == kInlineBlank;
}

// The inline id of `term` when it has one (canonical xsd:integer in range, or a blank node
// labelled "b<digits>" as the store writes them).
std::optional<std::uint64_t> inline_id(const Term& term);

// Finds the id of `term` without creating it; 0 when the store has never seen it.
Result<std::uint64_t> find_term(MDB_txn* txn, const Env& env, const Term& term);

// Finds or creates the id of `term` (not a blank node: those are renamed by the caller).
// `pin` marks the term as used outside the indexes (source, context, datatype, buffers), which
// keeps it from collection. Ids found or created are remembered (intern_keyed).
Result<std::uint64_t> intern_term(Txn& txn, const Term& term, bool pin);

// The key of `term` in the write path's caches (Txn::term_ids, Env::term_cache): kind, value,
// datatype and language, and its hash. Written into `out`, whose text is cleared first.
void term_key(const Term& term, TermKey& out);

struct InternOptions {
  bool pin = false;           // as intern_term's `pin`
  bool remember_new = true;   // a term this call creates is kept in the process's cache once the
                              // transaction commits (predicates, classes, sensors: terms that
                              // repeat; not the fresh subject of each observation)
  bool check_iri = false;     // a new IRI is checked (uri::is_valid) as it enters the
                              // dictionary (R1): invalid_iri, and nothing is added
};

// intern_term with `key` = term_key(term) already made. Looks in the transaction's ids, then the
// process's cache (Env::term_cache), then the dictionary; what it finds or creates is remembered
// for the transaction and, after the commit, for the process.
Result<std::uint64_t> intern_keyed(Txn& txn, const Term& term, const TermKey& key,
                                   const InternOptions& options);

// Marks dictionary term `id` as pinned (see intern_term); inline ids need no pin.
Result<void> pin_term(Txn& txn, std::uint64_t id);

// True when dictionary term `id` is pinned: it will never be collected, so its id may be
// remembered across transactions.
Result<bool> is_pinned(MDB_txn* txn, const Env& env, std::uint64_t id);

// Removes dictionary term `id` when no record refers to it any more and it is not pinned.
Result<void> collect_term_if_unused(Txn& txn, std::uint64_t id);

// Decodes ids to terms, remembering IRIs (predicates, sources and datatypes repeat endlessly).
// Valid for the life of one transaction.
class TermReader {
 public:
  TermReader(MDB_txn* txn, const Env& env) : txn_(txn), env_(env) {}
  // `repeating`: a term that comes back in record after record (a predicate, source, context or
  // datatype): looked up in, and added to, the process's cache of decoded terms (Env::decoded).
  // `remember` false: not kept for this reader's later calls either (a term read once to filter
  // on, which a scan meets for every item).
  Result<Term> get(std::uint64_t id, bool repeating = false, bool remember = true);
  Result<std::string> iri(std::uint64_t id);  // "" for id 0; repeating

 private:
  MDB_txn* txn_;
  const Env& env_;
  std::unordered_map<std::uint64_t, Term> memo_;
};

}  // namespace tahvel::node::detail
