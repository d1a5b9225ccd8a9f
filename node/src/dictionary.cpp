// Term dictionary; see dictionary.h.
#include "dictionary.h"

#include <algorithm>
#include <charconv>

#include "codec.h"
#include "rows.h"
#include "tahvel/uri/iri.h"

namespace tahvel::node::detail {
namespace {

constexpr std::uint8_t kPinned = 1;

// The dictionary row of term `id` into `v`, and the table it is in (`terms`, or `long_terms`
// for a long one, kLongTermBytes): LMDB's code, MDB_NOTFOUND in neither. Short terms, the most
// read, are looked up first.
int get_term_row(MDB_txn* txn, const Env& env, std::uint64_t id, MDB_val& v, MDB_dbi* table = nullptr) {
  MDB_val k = val(id);
  int rc = mdb_get(txn, env.terms, &k, &v);
  if (table) *table = env.terms;
  if (rc != MDB_NOTFOUND || env.long_terms == 0) return rc;
  if (table) *table = env.long_terms;
  return mdb_get(txn, env.long_terms, &k, &v);
}
constexpr std::int64_t kInlineIntMin = -(1ll << 59);
constexpr std::int64_t kInlineIntMax = (1ll << 59) - 1;

bool is_canonical_integer(std::string_view s) {
  if (s.empty()) return false;
  std::size_t i = s[0] == '-' ? 1 : 0;
  if (i == s.size()) return false;
  if (s[i] == '0') return s.size() == 1;  // "0" only; "-0" and "01" are not canonical
  for (; i < s.size(); ++i)
    if (s[i] < '0' || s[i] > '9') return false;
  return true;
}

// Language tags in lower case: they are case-insensitive (BCP 47), RDF 1.1 gives their value
// space in lower case, and the RDF parser lowers them; `en-US` from the C++ API is `en-us`, in a
// record as in a pattern.
void append_language(std::string& out, std::string_view language) {
  for (char c : language) out.push_back(c >= 'A' && c <= 'Z' ? static_cast<char>(c - 'A' + 'a') : c);
}

std::string payload(const Term& term, std::uint64_t datatype_id) {
  std::string out;
  out.reserve(term.value.size() + term.language.size() + 4);
  out.push_back(static_cast<char>(term.kind));
  if (term.kind == TermKind::literal) {
    codec::put_varint(out, datatype_id);
    out.push_back(static_cast<char>(term.language.size()));
    append_language(out, term.language);
  }
  out += term.value;
  return out;
}

bool has_explicit_datatype(const Term& term) {
  return term.kind == TermKind::literal && term.language.empty() && !term.datatype.empty() &&
         term.datatype != xsd::kString;
}

// Looks `bytes` up in term_hash; returns the id or 0, and with `pinned` whether the term is.
Result<std::uint64_t> lookup_payload(MDB_txn* txn, const Env& env, std::string_view bytes,
                                     std::uint64_t hash, bool* pinned = nullptr) {
  MDB_cursor* cursor = nullptr;
  int rc = mdb_cursor_open(txn, env.term_hash, &cursor);
  if (rc != 0) return lmdb_fail(rc, "opening the term index");
  MDB_val k = val(hash), v;
  std::uint64_t found = 0;
  for (rc = mdb_cursor_get(cursor, &k, &v, MDB_SET_KEY); rc == 0;
       rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT_DUP)) {
    std::uint64_t id = u64(v);
    MDB_val tv;
    const int got = get_term_row(txn, env, id, tv);
    // A term that cannot be read (a damaged page) is said as such: passed over, it left the
    // transaction failed, and the next step said only MDB_BAD_TXN.
    if (got != 0 && got != MDB_NOTFOUND) {
      mdb_cursor_close(cursor);
      return lmdb_fail(got, "reading term " + std::to_string(id));
    }
    if (got == 0 && tv.mv_size >= 1 && view(tv).substr(1) == bytes) {
      found = id;
      if (pinned) *pinned = static_cast<const std::uint8_t*>(tv.mv_data)[0] & kPinned;
      break;
    }
  }
  mdb_cursor_close(cursor);
  if (rc != 0 && rc != MDB_NOTFOUND) return lmdb_fail(rc, "reading the term index");
  return found;
}

}  // namespace

Result<void> pin_term(Txn& txn, std::uint64_t id) {
  if (is_inline(id)) return {};
  MDB_val k = val(id), v;
  MDB_dbi table = 0;
  int rc = get_term_row(txn.raw(), txn.env(), id, v, &table);
  if (rc != 0) return lmdb_fail(rc, "reading term " + std::to_string(id));
  if (static_cast<const std::uint8_t*>(v.mv_data)[0] & kPinned) return {};
  std::string value(view(v));
  value[0] = static_cast<char>(value[0] | kPinned);
  MDB_val nv = val(value);
  rc = mdb_put(txn.raw(), table, &k, &nv, 0);
  if (rc != 0) return lmdb_fail(rc, "pinning term " + std::to_string(id));
  return {};
}

Result<bool> is_pinned(MDB_txn* txn, const Env& env, std::uint64_t id) {
  if (is_inline(id)) return false;
  MDB_val v;
  int rc = get_term_row(txn, env, id, v);
  if (rc == MDB_NOTFOUND) return false;
  if (rc != 0) return lmdb_fail(rc, "reading term " + std::to_string(id));
  return (static_cast<const std::uint8_t*>(v.mv_data)[0] & kPinned) != 0;
}

namespace {

Result<bool> index_has(MDB_txn* txn, MDB_dbi dbi, std::uint64_t id) {
  MDB_val k = val(id), v;
  int rc = mdb_get(txn, dbi, &k, &v);
  if (rc == MDB_NOTFOUND) return false;
  if (rc != 0) return lmdb_fail(rc, "reading an index");
  return true;
}

}  // namespace

std::optional<std::uint64_t> inline_id(const Term& term) {
  if (term.kind == TermKind::blank) {
    std::string_view label = term.value;
    if (label.size() < 2 || label[0] != 'b' || label[1] == '0') return std::nullopt;
    std::uint64_t n = 0;
    auto [end, ec] = std::from_chars(label.data() + 1, label.data() + label.size(), n);
    if (ec != std::errc() || end != label.data() + label.size() || n > kInlinePayloadMask) return std::nullopt;
    return inline_blank(n);
  }
  if (term.kind == TermKind::literal && term.language.empty() && term.datatype == xsd::kInteger &&
      is_canonical_integer(term.value)) {
    std::int64_t v = 0;
    auto [end, ec] = std::from_chars(term.value.data(), term.value.data() + term.value.size(), v);
    if (ec != std::errc() || v < kInlineIntMin || v > kInlineIntMax) return std::nullopt;
    return kInlineBit | (kInlineInteger << kInlineKindShift) |
           (static_cast<std::uint64_t>(v) & kInlinePayloadMask);
  }
  return std::nullopt;
}

Result<std::uint64_t> find_term(MDB_txn* txn, const Env& env, const Term& term) {
  if (auto id = inline_id(term)) return *id;
  if (term.kind == TermKind::blank) return std::uint64_t{0};
  std::uint64_t datatype_id = 0;
  if (has_explicit_datatype(term)) {
    auto dt = find_term(txn, env, Term::iri(term.datatype));
    if (!dt) return dt;
    if (*dt == 0) return std::uint64_t{0};
    datatype_id = *dt;
  }
  std::string bytes = payload(term, datatype_id);
  auto found = lookup_payload(txn, env, bytes, codec::hash64(bytes));
  // A literal stored through the C++ API before tags were kept in lower case has its tag as
  // given: found so when the lowered form is not there (a pattern of either case finds it).
  if (found && *found == 0 && std::any_of(term.language.begin(), term.language.end(), [](char c) { return c >= 'A' && c <= 'Z'; })) {
    std::string as_given = bytes;
    as_given.replace(as_given.size() - term.value.size() - term.language.size(), term.language.size(), term.language);
    return lookup_payload(txn, env, as_given, codec::hash64(as_given));
  }
  return found;
}

void term_key(const Term& term, TermKey& out) {
  std::string& key = out.text;
  key.clear();
  key.reserve(term.value.size() + term.datatype.size() + term.language.size() + 3);
  key.push_back(static_cast<char>(term.kind));
  key += term.value;
  key.push_back('\0');
  key += term.datatype;
  key.push_back('\0');
  append_language(key, term.language);
  out.hash = std::hash<std::string_view>{}(key);
}

Result<std::uint64_t> intern_term(Txn& txn, const Term& term, bool pinned) {
  if (auto id = inline_id(term)) return *id;
  TermKey key;
  term_key(term, key);
  return intern_keyed(txn, term, key, {.pin = pinned});
}

namespace {

// Remembers `id` for the rest of the transaction and, once it commits, for the process.
constexpr std::size_t kLongestTermCached = 512;

void remember(Txn& txn, const TermKey& key, std::uint64_t id, bool pinned, bool beyond_txn) {
  auto [known, fresh] = txn.term_ids.try_emplace(key, Txn::KnownTerm{id, pinned});
  if (!fresh && pinned) known->second.pinned = true;
  // The process's cache is for writers, sources, predicates and classes, which come again; a
  // long literal seldom does, and 65,536 of them (its bound in entries) could be gigabytes.
  if (key.text.size() > kLongestTermCached) return;
  if (pinned) {
    txn.staged_pinned.try_emplace(key, id);
  } else if (beyond_txn) {
    txn.staged_unpinned.try_emplace(key, id);
  }
}

}  // namespace

Result<std::uint64_t> intern_keyed(Txn& txn, const Term& term, const TermKey& key,
                                   const InternOptions& options) {
  if (auto id = inline_id(term)) return *id;
  const bool pinned = options.pin;
  Env& env = txn.env();
  // Known in this transaction, or committed and known to the process: no B-tree search. A
  // term must be known pinned to skip the search when the caller pins it.
  if (auto it = txn.term_ids.find(key); it != txn.term_ids.end()) {
    if (!pinned || it->second.pinned) return it->second.id;
  }
  bool cached_pinned = false;
  if (std::uint64_t id = env.term_cache.find(key, TermCache::generation(txn.counters), &cached_pinned)) {
    if (pinned && !cached_pinned) {
      if (auto p = pin_term(txn, id); !p) return unexpected(p.error());
      remember(txn, key, id, true, true);  // pinned now: the process learns it after the commit
      return id;
    }
    // Already known to the process: remembered for this transaction only, not staged again.
    auto [known, fresh] = txn.term_ids.try_emplace(key, Txn::KnownTerm{id, cached_pinned});
    if (!fresh && cached_pinned) known->second.pinned = true;
    return id;
  }
  std::uint64_t datatype_id = 0;
  if (has_explicit_datatype(term)) {
    const Term datatype = Term::iri(term.datatype);
    TermKey datatype_key;
    term_key(datatype, datatype_key);
    auto dt = intern_keyed(txn, datatype, datatype_key, {.pin = true, .check_iri = options.check_iri});
    if (!dt) return dt;
    datatype_id = *dt;
  }
  std::string bytes = payload(term, datatype_id);
  std::uint64_t hash = codec::hash64(bytes);
  bool was_pinned = false;
  auto existing = lookup_payload(txn.raw(), env, bytes, hash, &was_pinned);
  if (!existing) return existing;
  if (*existing != 0) {
    if (pinned && !was_pinned) {
      if (auto p = pin_term(txn, *existing); !p) return unexpected(p.error());
    }
    remember(txn, key, *existing, pinned || was_pinned, true);
    return *existing;
  }
  // A new IRI is checked once, as it enters the dictionary (R1); terms already there were
  // checked when they came. Parsing alone decides; normalize only words the refusal.
  if (options.check_iri && term.kind == TermKind::iri && !uri::is_valid(term.value)) {
    auto n = uri::normalize(term.value);
    return fail(Errc::invalid_iri, n ? "invalid IRI <" + term.value + ">" : n.error().message);
  }
  std::uint64_t id = txn.counters.next_term++;
  std::string value;
  value.reserve(bytes.size() + 1);
  value.push_back(static_cast<char>(pinned ? kPinned : 0));
  value += bytes;
  MDB_val k = val(id), v = val(value);
  // Ids rise in either table: appended, each fills its pages.
  const MDB_dbi table = value.size() >= kLongTermBytes && txn.env().long_terms != 0 ? txn.env().long_terms : txn.env().terms;
  int rc = mdb_put(txn.raw(), table, &k, &v, MDB_APPEND);
  if (rc != 0) return lmdb_fail(rc, "adding a term");
  MDB_val hk = val(hash), hv = val(id);
  rc = mdb_put(txn.raw(), txn.env().term_hash, &hk, &hv, 0);
  if (rc != 0) return lmdb_fail(rc, "indexing a term");
  ++txn.counters.terms;
  remember(txn, key, id, pinned, options.remember_new);
  return id;
}

Result<void> collect_term_if_unused(Txn& txn, std::uint64_t id) {
  if (id == 0 || is_inline(id)) return {};
  if (auto f = flush_index(txn); !f) return f;
  MDB_txn* raw = txn.raw();
  Env& env = txn.env();
  MDB_val k = val(id), v;
  MDB_dbi table = 0;
  int rc = get_term_row(raw, env, id, v, &table);
  if (rc == MDB_NOTFOUND) return {};
  if (rc != 0) return lmdb_fail(rc, "reading term " + std::to_string(id));
  if (static_cast<const std::uint8_t*>(v.mv_data)[0] & kPinned) return {};
  for (MDB_dbi idx : {env.idx_s, env.idx_p, env.idx_o}) {
    auto used = index_has(raw, idx, id);
    if (!used) return unexpected(used.error());
    if (*used) return {};
  }
  std::string bytes(view(v).substr(1));
  std::uint64_t hash = codec::hash64(bytes);
  MDB_val hk = val(hash), hv = val(id);
  rc = mdb_del(raw, env.term_hash, &hk, &hv);
  if (rc != 0 && rc != MDB_NOTFOUND) return lmdb_fail(rc, "unindexing a term");
  rc = mdb_del(raw, table, &k, nullptr);
  if (rc != 0) return lmdb_fail(rc, "removing a term");
  --txn.counters.terms;
  // Ids seen before this collection may name the collected term: forget them (the process
  // cache ignores unpinned entries from now on, as the collection generation moved).
  txn.term_ids.clear();
  txn.staged_unpinned.clear();
  return {};
}

Result<Term> TermReader::get(std::uint64_t id, bool repeating, bool remember) {
  if (is_inline(id)) {
    std::uint64_t kind = (id >> kInlineKindShift) & 7;
    std::uint64_t bits = id & kInlinePayloadMask;
    if (kind == kInlineBlank) return Term::blank("b" + std::to_string(bits));
    // Sign-extend the 60-bit payload.
    auto v = static_cast<std::int64_t>(bits << 4) >> 4;
    return Term::integer(v);
  }
  if (auto it = memo_.find(id); it != memo_.end()) return it->second;
  if (repeating) {
    Term cached;
    if (env_.decoded.find(id, cached)) {
      memo_.emplace(id, cached);
      return cached;
    }
    // Only a snapshot's terms are shared: the writer's own transaction may hold ids that an
    // abort would hand out again.
    if (env_.writing.load(std::memory_order_relaxed) != txn_) {
      auto term = get(id, false);
      if (term) env_.decoded.add(id, *term);
      return term;
    }
  }
  MDB_val v;
  int rc = get_term_row(txn_, env_, id, v);
  if (rc != 0) return lmdb_fail(rc, "reading term " + std::to_string(id));
  std::string_view bytes = view(v);
  if (bytes.size() < 2) return fail(Errc::corrupt, "term " + std::to_string(id) + " is truncated");
  auto kind = static_cast<TermKind>(bytes[1]);
  std::size_t pos = 2;
  if (kind != TermKind::literal) {
    Term term{kind, std::string(bytes.substr(pos)), {}, {}};
    if (remember) memo_.emplace(id, term);
    return term;
  }
  std::uint64_t datatype_id = 0;
  if (!codec::get_varint(bytes, pos, datatype_id) || pos >= bytes.size())
    return fail(Errc::corrupt, "literal term " + std::to_string(id) + " is truncated");
  std::size_t lang_len = static_cast<std::uint8_t>(bytes[pos++]);
  if (pos + lang_len > bytes.size()) return fail(Errc::corrupt, "literal term " + std::to_string(id) + " is truncated");
  Term term = Term::literal(std::string(bytes.substr(pos + lang_len)));
  term.language = std::string(bytes.substr(pos, lang_len));
  if (datatype_id != 0) {
    auto dt = iri(datatype_id);
    if (!dt) return unexpected(dt.error());
    term.datatype = *dt;
  }
  return term;
}

Result<std::string> TermReader::iri(std::uint64_t id) {
  if (id == 0) return std::string();
  auto term = get(id, true);
  if (!term) return unexpected(term.error());
  return term->value;
}

}  // namespace tahvel::node::detail
