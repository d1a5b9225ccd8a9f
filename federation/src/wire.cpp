#include "tahvel/federation/wire.h"

#include <algorithm>

#include "wire_common.h"

namespace tahvel::federation::wire {
namespace {

class Out {
 public:
  Out& u8(std::uint8_t v) { return uint(v, 1); }
  Out& u32(std::uint32_t v) { return uint(v, 4); }
  Out& u64(std::uint64_t v) { return uint(v, 8); }
  Out& i64(std::int64_t v) { return uint(static_cast<std::uint64_t>(v), 8); }
  Out& str(std::string_view s) {
    u32(static_cast<std::uint32_t>(s.size()));
    bytes_.append(s);
    return *this;
  }
  Out& term(const node::Term& t) {
    u8(static_cast<std::uint8_t>(t.kind));
    str(t.value);
    if (t.kind == node::TermKind::literal) str(t.datatype).str(t.language);
    return *this;
  }
  Out& opt_term(const std::optional<node::Term>& t) {
    u8(t ? 1 : 0);
    if (t) term(*t);
    return *this;
  }
  Out& opt_i64(const std::optional<std::int64_t>& v) {
    u8(v ? 1 : 0);
    if (v) i64(*v);
    return *this;
  }
  std::string take() { return std::move(bytes_); }

 private:
  Out& uint(std::uint64_t v, int width) {
    for (int i = 0; i < width; ++i) bytes_.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
    return *this;
  }
  std::string bytes_;
};

// Reads fields in order; the first failure is remembered and every later read is a no-op, so a
// decoder reads everything and checks once.
class In {
 public:
  In(std::string_view bytes, const char* what) : bytes_(bytes), what_(what) {}

  std::uint64_t uint(int width, const char* field) {
    if (!need(width, field)) return 0;
    std::uint64_t v = 0;
    for (int i = 0; i < width; ++i) v |= std::uint64_t{static_cast<unsigned char>(bytes_[pos_ + i])} << (8 * i);
    pos_ += width;
    return v;
  }
  std::uint8_t u8(const char* f) { return static_cast<std::uint8_t>(uint(1, f)); }
  std::uint32_t u32(const char* f) { return static_cast<std::uint32_t>(uint(4, f)); }
  std::uint64_t u64(const char* f) { return uint(8, f); }
  std::int64_t i64(const char* f) { return static_cast<std::int64_t>(uint(8, f)); }
  std::string str(const char* field) {
    std::uint32_t n = u32(field);
    if (!need(n, field)) return {};
    std::string s(bytes_.substr(pos_, n));
    // Every string on the wire is text (IRIs, literals, messages): a store refuses the rest.
    if (const std::size_t at = node::ill_formed_utf8_at(s); at != std::string::npos)
      fail(field, "not UTF-8 (byte " + std::to_string(at) + " of " + std::to_string(n) + ")");
    pos_ += n;
    return s;
  }
  node::Term term(const char* field) {
    node::Term t;
    std::uint8_t kind = u8(field);
    if (ok() && (kind < 1 || kind > 3)) fail(field, "term kind " + std::to_string(kind) + " unknown");
    t.kind = static_cast<node::TermKind>(kind);
    t.value = str(field);
    if (t.kind == node::TermKind::literal) {
      t.datatype = str(field);
      t.language = str(field);
    }
    return t;
  }
  std::optional<node::Term> opt_term(const char* field) {
    if (u8(field) == 0) return std::nullopt;
    return term(field);
  }
  std::optional<std::int64_t> opt_i64(const char* field) {
    if (u8(field) == 0) return std::nullopt;
    return i64(field);
  }
  // A count of elements that each take at least `min_bytes`: refuses counts the body cannot
  // hold, so a corrupt count never makes us reserve gigabytes.
  std::uint32_t count(const char* field, std::size_t min_bytes) {
    std::uint32_t n = u32(field);
    if (ok() && n > (bytes_.size() - pos_) / min_bytes) fail(field, "count " + std::to_string(n) + " exceeds the body");
    return ok() ? n : 0;
  }

  // Remembers the first failure: what was wrong with `field`, and where.
  void fail(const char* field, const std::string& why) {
    if (!error_)
      error_ = Error{Errc::syntax, std::string(what_) + " body: " + why + " in field '" + field +
                                       "' at byte " + std::to_string(pos_)};
  }

  bool ok() const { return !error_; }
  bool at_end() const { return pos_ == bytes_.size(); }
  template <class T>
  Result<T> finish(T value) {
    if (!error_ && pos_ != bytes_.size())
      fail("end", std::to_string(bytes_.size() - pos_) + " stray bytes");
    if (error_) return Unexpected<Error>{*error_};
    return value;
  }

 private:
  bool need(std::size_t n, const char* field) {
    if (error_) return false;
    if (bytes_.size() - pos_ < n) {
      fail(field, "truncated");
      return false;
    }
    return true;
  }

  std::string_view bytes_;
  const char* what_;
  std::size_t pos_ = 0;
  std::optional<Error> error_;
};

constexpr std::size_t kMinTripleBytes = 3 * 5;
constexpr std::size_t kMinRecordBytes = kMinTripleBytes + 8 * 5 + 4 + 4 + 1;

}  // namespace

// The item body's flags byte (docs/protocol.md, "Bodies").
constexpr std::uint8_t kItemPersistent = 1;
constexpr std::uint8_t kItemRemoval = 2;
constexpr std::uint8_t kItemSpan = 4;  // i64 span follows asserted_at (node::Item::span)

std::string encode_item(const ItemBody& body) {
  Out out;
  out.str(body.source).str(body.item.context);
  out.u8((body.item.persistent ? kItemPersistent : 0) | (body.removal ? kItemRemoval : 0) |
         (body.item.span != 0 ? kItemSpan : 0));
  out.opt_i64(body.item.asserted_at);
  if (body.item.span != 0) out.i64(body.item.span);
  out.u32(static_cast<std::uint32_t>(body.item.triples.size()));
  for (const auto& t : body.item.triples) out.term(t.s).term(t.p).term(t.o);
  if (body.removal) {
    for (std::size_t i = 0; i < body.item.triples.size(); ++i) out.u32(i < body.positions.size() ? body.positions[i] : 0);
  }
  return out.take();
}

Result<ItemBody> decode_item(std::string_view bytes) {
  In in(bytes, "item");
  ItemBody body;
  body.source = in.str("source");
  body.item.context = in.str("context");
  const std::uint8_t flags = in.u8("flags");
  if (flags & ~(kItemPersistent | kItemRemoval | kItemSpan))
    in.fail("flags", "unknown flag bits " + std::to_string(flags));
  body.item.persistent = (flags & kItemPersistent) != 0;
  body.removal = (flags & kItemRemoval) != 0;
  body.item.asserted_at = in.opt_i64("asserted_at");
  if (flags & kItemSpan) {
    body.item.span = in.i64("span");
    // The store refuses these too; said here with the field's place, as a malformed body.
    if (in.ok() && body.item.span <= 0) in.fail("span", "not positive: " + std::to_string(body.item.span));
  }
  std::uint32_t n = in.count("triples", kMinTripleBytes);
  body.item.triples.reserve(n);
  for (std::uint32_t i = 0; i < n && in.ok(); ++i) {
    node::Triple t;
    t.s = in.term("subject");
    t.p = in.term("predicate");
    t.o = in.term("object");
    body.item.triples.push_back(std::move(t));
  }
  if (body.removal) {
    for (std::uint32_t i = 0; i < n && in.ok(); ++i) body.positions.push_back(in.u32("position"));
  }
  return in.finish(std::move(body));
}

Result<std::string> encode_query(const QueryBody& body, std::uint16_t version) {
  if (version < 4 && (!body.source.empty() || !body.under.empty()))
    return node::fail(Errc::invalid_argument, "a query by source or by subject (--source, --under) needs protocol version 4, not " +
                                                  std::to_string(version));
  Out out;
  out.str(body.origin).str(body.target).opt_term(body.s).opt_term(body.p).opt_term(body.o);
  out.opt_i64(body.since).opt_i64(body.until).u32(body.cascade).u64(body.limit);
  out.str(body.area).opt_i64(body.floor);
  if (version >= 4) out.str(body.source).str(body.under);
  return out.take();
}

Result<QueryBody> decode_query(std::string_view bytes, std::uint16_t version) {
  In in(bytes, "query");
  QueryBody body;
  body.origin = in.str("origin");
  body.target = in.str("target");
  body.s = in.opt_term("s");
  body.p = in.opt_term("p");
  body.o = in.opt_term("o");
  body.since = in.opt_i64("since");
  body.until = in.opt_i64("until");
  body.cascade = in.u32("cascade");
  body.limit = in.u64("limit");
  body.area = in.str("area");
  body.floor = in.opt_i64("floor");
  if (version >= 4) {
    body.source = in.str("source");
    body.under = in.str("under");
  }
  return in.finish(std::move(body));
}

std::string encode_answer(const AnswerBody& body, std::uint16_t version) {
  Out out;
  out.str(body.origin).u8(body.last ? 1 : 0).u32(static_cast<std::uint32_t>(body.records.size()));
  for (const auto& r : body.records) {
    out.term(r.triple.s).term(r.triple.p).term(r.triple.o);
    out.u64(r.meta.id).u64(r.meta.item).i64(r.meta.stored_at).i64(r.meta.asserted_at);
    if (version >= 3) out.i64(r.meta.span);
    out.str(r.meta.source).str(r.meta.context).u8(r.meta.persistent ? 1 : 0);
  }
  return out.take();
}

Result<AnswerBody> decode_answer(std::string_view bytes, std::uint16_t version) {
  In in(bytes, "answer");
  AnswerBody body;
  body.origin = in.str("origin");
  body.last = in.u8("last") != 0;
  std::uint32_t n = in.count("records", kMinRecordBytes - (version >= 3 ? 0 : 8));
  body.records.reserve(n);
  for (std::uint32_t i = 0; i < n && in.ok(); ++i) {
    node::Record r;
    r.triple.s = in.term("subject");
    r.triple.p = in.term("predicate");
    r.triple.o = in.term("object");
    r.meta.id = in.u64("id");
    r.meta.item = in.u64("item");
    r.meta.stored_at = in.i64("stored_at");
    r.meta.asserted_at = in.i64("asserted_at");
    if (version >= 3) r.meta.span = in.i64("span");
    if (in.ok() && r.meta.span < 0) in.fail("span", "negative: " + std::to_string(r.meta.span));
    r.meta.source = in.str("source");
    r.meta.context = in.str("context");
    r.meta.persistent = in.u8("persistent") != 0;
    body.records.push_back(std::move(r));
  }
  return in.finish(std::move(body));
}

std::string encode_error(const ErrorBody& body) {
  return Out().str(body.code).str(body.message).str(body.origin).take();
}

Result<ErrorBody> decode_error(std::string_view bytes) {
  In in(bytes, "error");
  ErrorBody body;
  body.code = in.str("code");
  body.message = in.str("message");
  body.origin = in.str("origin");
  return in.finish(std::move(body));
}

std::string encode_state(const StateBody& body) {
  Out out;
  out.str(body.software_version).u64(body.outbox_depth);
  // The store ids follow only when there are any: a body without them is what a link from
  // before store ids sends, and reads the same.
  if (!body.store_id.empty() || !body.peer_store_id.empty() || body.room) out.str(body.store_id).str(body.peer_store_id);
  if (body.room) out.u64(body.room->used_bytes).u64(body.room->data_bytes).u64(body.room->max_bytes).u64(body.room->disk_free_bytes);
  return out.take();
}

Result<StateBody> decode_state(std::string_view bytes, std::uint16_t version) {
  In in(bytes, "state");
  StateBody body;
  body.software_version = in.str("software_version");
  body.outbox_depth = in.u64("outbox_depth");
  if (in.ok() && !in.at_end()) {
    // A store's id is 32 lowercase hex digits (node::Node::store_id), or none from a peer of
    // before store ids: another is a body damaged or made up. Taken, a hello whose id had one
    // digit changed was "another store" of the child, and a few made a conflict that kept two
    // children out for two minutes (an exploratory run of session 85).
    const auto store_id = [&](const char* field) {
      std::string id = in.str(field);
      const bool hex = std::all_of(id.begin(), id.end(), [](char c) { return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'); });
      if (in.ok() && !id.empty() && (id.size() != 32 || !hex))
        in.fail(field, "'" + printable(id, 64) + "' is not a store id (32 lowercase hex digits)");
      return id;
    };
    body.store_id = store_id("store_id");
    body.peer_store_id = store_id("peer_store_id");
  }
  if (version >= 5 && in.ok() && !in.at_end()) {
    StoreRoom room;
    room.used_bytes = in.u64("store_used_bytes");
    room.data_bytes = in.u64("store_data_bytes");
    room.max_bytes = in.u64("store_max_bytes");
    room.disk_free_bytes = in.u64("disk_free_bytes");
    body.room = room;
  }
  return in.finish(std::move(body));
}

}  // namespace tahvel::federation::wire
