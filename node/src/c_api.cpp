// The C API (tahvel.h) over the C++ node library (node.h): opaque handles that own a Node or an
// Agent, N-Triples text in and out, tahvel_status codes that are the C++ Errc values, and a
// thread-local message for the last failure.
//
// Why it is built this way:
//  - Every entry point runs inside guarded(), which turns any C++ exception into a status and a
//    message: no exception may unwind through a C caller's frames.
//  - Live handles are kept in a registry so that NULL and already-closed handles are refused
//    with TAHVEL_INVALID_ARGUMENT instead of being dereferenced (STYLE: "a stale handle is an
//    error, not a crash"). The lookup is one mutex and one hash probe per call, small beside
//    an LMDB transaction.
//  - Terms in patterns are parsed by serd through parse_rdf, by placing the caller's term in the
//    object position of a one-line N-Triples document: no hand-written RDF parsing here.
//  - Workload: a few calls per item from small agents; clarity over micro-optimisation.

#include "tahvel/node/tahvel.h"

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <memory>
#include <mutex>
#include <new>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <typeindex>
#include <typeinfo>
#include <unordered_map>
#include <utility>
#include <vector>

#include "tahvel/node/error.h"
#include "tahvel/node/format.h"
#include "tahvel/node/node.h"
#include "tahvel/node/stop_signal.h"
#include "tahvel/node/term.h"
#include "tahvel/uri/iri.h"

struct tahvel_node {
  tahvel::node::Node node;
};

struct tahvel_agent {
  tahvel::node::Agent agent;
  tahvel::uri::PrefixMap prefixes;  // the node's prefixes when the handle was opened (Turtle)
};

namespace {

using tahvel::node::Errc;
using tahvel::node::Error;
using tahvel::node::Pattern;
using tahvel::node::Record;
using tahvel::node::Term;

// The C codes are the C++ codes: a status is a static_cast of an Errc.
static_assert(TAHVEL_INVALID_ARGUMENT == static_cast<int>(Errc::invalid_argument));
static_assert(TAHVEL_INVALID_IRI == static_cast<int>(Errc::invalid_iri));
static_assert(TAHVEL_SYNTAX == static_cast<int>(Errc::syntax));
static_assert(TAHVEL_LITERAL_TOO_LARGE == static_cast<int>(Errc::literal_too_large));
static_assert(TAHVEL_STORE_FULL == static_cast<int>(Errc::store_full));
static_assert(TAHVEL_NOT_FOUND == static_cast<int>(Errc::not_found));
static_assert(TAHVEL_EXISTS == static_cast<int>(Errc::exists));
static_assert(TAHVEL_IO == static_cast<int>(Errc::io));
static_assert(TAHVEL_CORRUPT == static_cast<int>(Errc::corrupt));
static_assert(TAHVEL_TIMEOUT == static_cast<int>(Errc::timeout));
static_assert(TAHVEL_VERSION == static_cast<int>(Errc::version));

thread_local std::string t_last_error;

// Records `message` as this thread's last error. Never throws: if the message cannot be
// allocated, the previous one is replaced by a static fallback.
tahvel_status set_error(tahvel_status status, const char* fn, std::string_view message) noexcept {
  try {
    std::string text(fn);
    text += ": ";
    text += message;
    t_last_error = std::move(text);
  } catch (...) {
    t_last_error.clear();
    try {
      t_last_error = "out of memory while recording an error";
    } catch (...) {
    }
  }
  return status;
}

tahvel_status set_error(const char* fn, const Error& error) noexcept {
  return set_error(static_cast<tahvel_status>(error.code), fn, error.message);
}

// Runs `body` and converts any exception into a status: exceptions never cross the C boundary.
template <class Body>
tahvel_status guarded(const char* fn, Body&& body) noexcept {
  try {
    return body();
  } catch (const std::bad_alloc&) {
    return set_error(TAHVEL_NO_MEMORY, fn, "out of memory");
  } catch (const std::exception& e) {
    return set_error(TAHVEL_INTERNAL, fn, std::string("unexpected exception: ") + e.what());
  } catch (...) {
    return set_error(TAHVEL_INTERNAL, fn, "unexpected exception of unknown type");
  }
}

// --- Handle registry ----------------------------------------------------------------------

// Handles by address and kind: in an FFI every handle is a bare pointer (ctypes' c_void_p), and
// a node handle passed where an agent's goes must be refused, not used as one.
class Registry {
 public:
  template <class Handle>
  void add(const Handle* handle) {
    std::lock_guard lock(mutex_);
    live_.insert_or_assign(handle, std::type_index(typeid(Handle)));
  }
  // True when `handle` was live as a Handle and is now removed.
  template <class Handle>
  bool remove(const Handle* handle) noexcept {
    std::lock_guard lock(mutex_);
    auto it = live_.find(handle);
    if (it == live_.end() || it->second != std::type_index(typeid(Handle))) return false;
    live_.erase(it);
    return true;
  }
  template <class Handle>
  bool contains(const Handle* handle) const noexcept {
    if (handle == nullptr) return false;
    std::lock_guard lock(mutex_);
    auto it = live_.find(handle);
    return it != live_.end() && it->second == std::type_index(typeid(Handle));
  }

 private:
  mutable std::mutex mutex_;
  std::unordered_map<const void*, std::type_index> live_;
};

// Never destroyed, so that handles closed from other static destructors or atexit handlers
// still find it.
Registry& registry() {
  static Registry* instance = new Registry;
  return *instance;
}

// Registers a new handle and hands it to the caller; if registering throws, the handle is
// freed and the exception goes on to the boundary's catch.
template <class Handle>
tahvel_status publish(std::unique_ptr<Handle> handle, Handle** out) {
  registry().add(handle.get());
  *out = handle.release();
  return TAHVEL_OK;
}

tahvel_status bad_handle(const char* fn, const char* what) noexcept {
  return set_error(TAHVEL_INVALID_ARGUMENT, fn, std::string(what) + " handle is NULL or closed");
}

// --- Terms and text -----------------------------------------------------------------------

enum class Position { subject, predicate, object };

const char* position_name(Position position) {
  switch (position) {
    case Position::subject: return "subject";
    case Position::predicate: return "predicate";
    case Position::object: return "object";
  }
  return "term";
}

std::string_view trim(std::string_view text) {
  const auto space = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; };
  while (!text.empty() && space(text.front())) text.remove_prefix(1);
  while (!text.empty() && space(text.back())) text.remove_suffix(1);
  return text;
}

// The term goes after this prefix, in the object position, so that one parser handles IRIs,
// blank nodes and every form of literal; the position checks come after.
constexpr std::string_view kTermPrefix = "<urn:tahvel:c-api:s> <urn:tahvel:c-api:p> ";

// Rewrites parse_rdf's "term:LINE:COL: reason" into "at column N: reason" (or "at line L,
// column N" for a term of several lines), counted in the caller's term rather than in the
// snippet it was wrapped in.
std::string term_error(std::string_view message) {
  constexpr std::string_view head = "term:";
  auto number_at = [&](std::size_t& at) -> std::optional<long> {
    const std::size_t from = at;
    while (at < message.size() && message[at] >= '0' && message[at] <= '9') ++at;
    if (at == from || at - from > 9) return std::nullopt;
    return std::stol(std::string(message.substr(from, at - from)));
  };
  if (message.substr(0, head.size()) != head) return std::string(message);
  std::size_t at = head.size();
  const auto line = number_at(at);
  if (!line || message.substr(at, 1) != ":") return std::string(message);
  ++at;
  const auto column = number_at(at);
  if (!column || message.substr(at, 2) != ": ") return std::string(message);
  const std::string reason(message.substr(at + 2));
  if (*line > 1) return "at line " + std::to_string(*line) + ", column " + std::to_string(*column) + ": " + reason;
  const long in_term = *column - static_cast<long>(kTermPrefix.size());
  return "at column " + std::to_string(in_term < 1 ? 1 : in_term) + ": " + reason;
}

// Parses one N-Triples term for `position`; NULL or blank text means "any" (nullopt).
tahvel::node::Result<std::optional<Term>> parse_term(const char* text, Position position) {
  using tahvel::node::fail;
  if (text == nullptr || trim(text).empty()) return std::optional<Term>{};
  const std::string_view term = trim(text);
  std::string document(kTermPrefix);
  document.append(term).append(" .\n");
  tahvel::node::ParseOptions options;
  options.format = tahvel::node::Format::ntriples;
  options.source_name = "term";
  auto triples = tahvel::node::parse_rdf(document, options);
  const std::string quoted =
      std::string(position_name(position)) + " term '" + std::string(term) + "'";
  // The two slips a caller makes most, said as such: the parser's words for them ("invalid IRI
  // character" at a column past the term, "expected ':', '<', or '_'") name neither.
  if (term.front() == '<' && term.find('>') == std::string_view::npos)
    return fail(Errc::syntax, "invalid " + quoted + ": the IRI has no closing '>'");
  if (term.front() != '<' && term.front() != '"' && !term.starts_with("_:"))
    return fail(Errc::syntax, "invalid " + quoted + ": a term is written as N-Triples writes it: <IRI>, \"literal\" or _:label "
                              "(prefixed names such as ex:name, and bare IRIs or numbers, are not read here)");
  if (!triples) {
    const Error& error = triples.error();
    return fail(error.code, "invalid " + quoted + " " + term_error(error.message));
  }
  if (triples->size() != 1)
    return fail(Errc::invalid_argument, quoted + " is not exactly one term");
  Term parsed = std::move(triples->front().o);
  // Checked here, not where the term is first stored: a pattern's terms are stored in the
  // subscription's own item, whose error named its triple ("triple 2, object").
  if (parsed.is_iri() && !tahvel::uri::is_valid(parsed.value))
    return fail(Errc::invalid_iri, "invalid " + quoted + ": not an absolute IRI");
  if (parsed.is_literal() && !parsed.datatype.empty() && !tahvel::uri::is_valid(parsed.datatype))
    return fail(Errc::invalid_iri, "invalid " + quoted + ": its datatype is not an absolute IRI");
  if (position == Position::subject && parsed.is_literal())
    return fail(Errc::invalid_argument, quoted + ": a subject cannot be a literal");
  if (position == Position::predicate && !parsed.is_iri())
    return fail(Errc::invalid_argument, quoted + ": a predicate must be an IRI");
  return std::optional<Term>(std::move(parsed));
}

tahvel::node::Result<Pattern> parse_pattern(const char* s, const char* p, const char* o) {
  Pattern pattern;
  auto subject = parse_term(s, Position::subject);
  if (!subject) return tahvel::unexpected(std::move(subject).error());
  auto predicate = parse_term(p, Position::predicate);
  if (!predicate) return tahvel::unexpected(std::move(predicate).error());
  auto object = parse_term(o, Position::object);
  if (!object) return tahvel::unexpected(std::move(object).error());
  pattern.s = std::move(*subject);
  pattern.p = std::move(*predicate);
  pattern.o = std::move(*object);
  return pattern;
}

std::string to_ntriples(const std::vector<Record>& records) {
  std::string text;
  for (const Record& record : records) {
    text += record.triple.s.to_ntriples();
    text += ' ';
    text += record.triple.p.to_ntriples();
    text += ' ';
    text += record.triple.o.to_ntriples();
    text += " .\n";
  }
  return text;
}

// The records as N-Triples or JSON lines; nullopt for a format reads cannot produce.
std::optional<std::string> render(const std::vector<Record>& records, int format) {
  if (format == TAHVEL_FORMAT_NTRIPLES) return to_ntriples(records);
  if (format != TAHVEL_FORMAT_JSON) return std::nullopt;
  std::ostringstream out;
  {
    tahvel::node::RecordWriter writer(out, tahvel::node::Format::json);
    for (const Record& record : records) writer.write(record);
  }
  return std::move(out).str();
}

tahvel_status bad_format(const char* fn, int format) {
  return set_error(TAHVEL_INVALID_ARGUMENT, fn,
                   "format " + std::to_string(format) +
                       ": reads give TAHVEL_FORMAT_NTRIPLES or TAHVEL_FORMAT_JSON");
}

// Hands `text` to the caller as a malloc'd, NUL-terminated copy (freed with tahvel_free).
tahvel_status copy_out(const char* fn, const std::string& text, char** out, size_t* len_out) {
  if (out != nullptr) {
    char* copy = static_cast<char*>(std::malloc(text.size() + 1));
    if (copy == nullptr)
      return set_error(TAHVEL_NO_MEMORY, fn, "out of memory for the result text");
    std::memcpy(copy, text.data(), text.size());
    copy[text.size()] = '\0';
    *out = copy;
  }
  if (len_out != nullptr) *len_out = text.size();
  return TAHVEL_OK;
}

template <class T>
void clear(T* out) {
  if (out != nullptr) *out = T{};
}

// Context IRI as given by the caller: NULL or "" for none, angle brackets optional.
tahvel::node::Result<std::string> parse_context(const char* context) {
  if (context == nullptr) return std::string();
  std::string_view text = trim(context);
  if (text.empty()) return std::string();
  // "<>" is an empty IRI (a relative reference), not "no context": refused as "< >" is.
  if (text.size() >= 2 && text.front() == '<' && text.back() == '>')
    text = text.substr(1, text.size() - 2);
  // Parsing alone decides, as for every IRI the store takes (dictionary.cpp); normalize words
  // the refusal, as the C++ API does, its bytes escaped: the message named the IRI alone, and a
  // byte that was not UTF-8 went into it raw (a developer's probe of session 84).
  if (!tahvel::uri::is_valid(text)) {
    auto normal = tahvel::uri::normalize(text);
    return tahvel::node::fail(Errc::invalid_iri, "context: " + (normal ? "invalid IRI <" + *normal + ">" : normal.error().message));
  }
  return std::string(text);
}

tahvel::node::Result<std::optional<tahvel::node::Delivery>> take_waiting(
    tahvel::node::Agent& agent, int timeout_ms) {
  using namespace std::chrono;
  // No limit: a wait until something arrives, an error, or a signal handler (Agent::take).
  return agent.take(timeout_ms >= 0 ? milliseconds(timeout_ms) : milliseconds::max(), tahvel::node::Ack::manual);
}

}  // namespace

// --- Errors and memory ----------------------------------------------------------------------

extern "C" const char* tahvel_strerror(tahvel_status status) {
  switch (status) {
    case TAHVEL_OK: return "success";
    case TAHVEL_INVALID_ARGUMENT: return "invalid argument";
    case TAHVEL_INVALID_IRI: return "invalid IRI";
    case TAHVEL_SYNTAX: return "syntax error in RDF input";
    case TAHVEL_LITERAL_TOO_LARGE: return "literal larger than the node allows";
    case TAHVEL_STORE_FULL: return "store full";
    case TAHVEL_NOT_FOUND: return "no such node, item or record";
    case TAHVEL_EXISTS: return "a store already exists there";
    case TAHVEL_IO: return "input/output error";
    case TAHVEL_CORRUPT: return "store corrupt";
    case TAHVEL_TIMEOUT: return "timed out";
    case TAHVEL_VERSION: return "store written by an incompatible version";
    case TAHVEL_NO_MEMORY: return "out of memory";
    case TAHVEL_INTERNAL: return "internal error";
  }
  return "unknown status";
}

extern "C" const char* tahvel_last_error(void) { return t_last_error.c_str(); }

extern "C" void tahvel_free(void* ptr) { std::free(ptr); }

// --- Nodes ----------------------------------------------------------------------------------

namespace {

tahvel_status adopt_node(const char* fn, tahvel::node::Result<tahvel::node::Node> opened,
                         tahvel_node** out) {
  if (!opened) return set_error(fn, opened.error());
  return publish(std::unique_ptr<tahvel_node>(new tahvel_node{std::move(opened).value()}), out);
}

}  // namespace

extern "C" tahvel_status tahvel_node_open(const char* dir, tahvel_node** out) {
  static constexpr const char* fn = "tahvel_node_open";
  return guarded(fn, [&] {
    clear(out);
    if (dir == nullptr || out == nullptr)
      return set_error(TAHVEL_INVALID_ARGUMENT, fn, "dir and out must not be NULL");
    return adopt_node(fn, tahvel::node::Node::open(dir), out);
  });
}

extern "C" tahvel_status tahvel_node_init(const char* dir, const char* iri, tahvel_node** out) {
  static constexpr const char* fn = "tahvel_node_init";
  return guarded(fn, [&] {
    clear(out);
    if (dir == nullptr || iri == nullptr || out == nullptr)
      return set_error(TAHVEL_INVALID_ARGUMENT, fn, "dir, iri and out must not be NULL");
    tahvel::node::InitOptions options;
    options.iri = iri;
    return adopt_node(fn, tahvel::node::Node::init(dir, options), out);
  });
}

extern "C" void tahvel_node_close(tahvel_node* node) {
  if (registry().remove(node)) delete node;
}

extern "C" const char* tahvel_node_iri(const tahvel_node* node) {
  if (!registry().contains(node)) return nullptr;
  return node->node.iri().c_str();
}

namespace {

// tahvel_list and tahvel_list_as; `fn` names the one called in errors.
tahvel_status list_as(const char* fn, tahvel_node* node, const char* s, const char* p, const char* o, unsigned cascade,
                      size_t limit, int format, char** text_out, size_t* len_out) {
  return guarded(fn, [&] {
    clear(text_out);
    clear(len_out);
    if (!registry().contains(node)) return bad_handle(fn, "node");
    if (text_out == nullptr)
      return set_error(TAHVEL_INVALID_ARGUMENT, fn, std::string(fn == std::string_view("tahvel_list") ? "ntriples_out" : "text_out") +
                                                        " must not be NULL");
    if (format != TAHVEL_FORMAT_NTRIPLES && format != TAHVEL_FORMAT_JSON) return bad_format(fn, format);
    auto pattern = parse_pattern(s, p, o);
    if (!pattern) return set_error(fn, pattern.error());
    auto snapshot = node->node.snapshot();
    if (!snapshot) return set_error(fn, snapshot.error());
    tahvel::node::ListOptions options;
    options.cascade = cascade;
    options.limit = limit;
    auto records = snapshot->list(*pattern, options);
    if (!records) return set_error(fn, records.error());
    return copy_out(fn, *render(*records, format), text_out, len_out);
  });
}

}  // namespace

extern "C" tahvel_status tahvel_list(tahvel_node* node, const char* s, const char* p,
                                     const char* o, unsigned cascade, size_t limit,
                                     char** ntriples_out, size_t* len_out) {
  return list_as("tahvel_list", node, s, p, o, cascade, limit, TAHVEL_FORMAT_NTRIPLES, ntriples_out, len_out);
}

extern "C" tahvel_status tahvel_list_as(tahvel_node* node, const char* s, const char* p,
                                        const char* o, unsigned cascade, size_t limit, int format,
                                        char** text_out, size_t* len_out) {
  return list_as("tahvel_list_as", node, s, p, o, cascade, limit, format, text_out, len_out);
}

extern "C" tahvel_status tahvel_watch(tahvel_node* node, uint64_t bookmark, int timeout_ms,
                                      size_t limit, char** json_out, size_t* len_out,
                                      uint64_t* bookmark_out) {
  static constexpr const char* fn = "tahvel_watch";
  return guarded(fn, [&] {
    clear(json_out);
    clear(len_out);
    if (bookmark_out != nullptr) *bookmark_out = bookmark;
    if (!registry().contains(node)) return bad_handle(fn, "node");
    // Without somewhere to put the changes the bookmark would move past changes nobody saw.
    if (json_out == nullptr) return set_error(TAHVEL_INVALID_ARGUMENT, fn, "json_out must not be NULL");
    using namespace std::chrono;
    // Negative: no limit (Node::watch takes milliseconds::max() so). One call: a signal that
    // ends the wait must reach the caller, whose handler set a stop flag.
    auto changes = node->node.watch(bookmark, timeout_ms >= 0 ? milliseconds(timeout_ms) : milliseconds::max(), limit);
    if (!changes) return set_error(fn, changes.error());
    std::ostringstream out;
    {
      tahvel::node::RecordWriter writer(out, tahvel::node::Format::json);
      for (const tahvel::node::Change& change : *changes) writer.write(change);
    }
    tahvel_status status = copy_out(fn, std::move(out).str(), json_out, len_out);
    if (status == TAHVEL_OK && bookmark_out != nullptr && !changes->empty())
      *bookmark_out = changes->back().seq;
    return status;
  });
}

extern "C" tahvel_status tahvel_remove_item(tahvel_node* node, uint64_t item, unsigned cascade,
                                            uint64_t* removed_out) {
  static constexpr const char* fn = "tahvel_remove_item";
  return guarded(fn, [&] {
    clear(removed_out);
    if (!registry().contains(node)) return bad_handle(fn, "node");
    auto removed = node->node.remove_item(item, cascade);
    if (!removed) return set_error(fn, removed.error());
    if (removed_out != nullptr) *removed_out = *removed;
    return TAHVEL_OK;
  });
}

// --- Agents ---------------------------------------------------------------------------------

extern "C" tahvel_status tahvel_agent_open(tahvel_node* node, const char* id, tahvel_agent** out) {
  static constexpr const char* fn = "tahvel_agent_open";
  return guarded(fn, [&] {
    clear(out);
    if (!registry().contains(node)) return bad_handle(fn, "node");
    if (id == nullptr || out == nullptr)
      return set_error(TAHVEL_INVALID_ARGUMENT, fn, "id and out must not be NULL");
    auto agent = node->node.agent(id);
    if (!agent) return set_error(fn, agent.error());
    return publish(std::unique_ptr<tahvel_agent>(new tahvel_agent{std::move(agent).value(), node->node.prefixes()}), out);
  });
}

extern "C" void tahvel_agent_close(tahvel_agent* agent) {
  if (registry().remove(agent)) delete agent;
}

extern "C" const char* tahvel_agent_iri(const tahvel_agent* agent) {
  if (!registry().contains(agent)) return nullptr;
  return agent->agent.iri().c_str();
}

extern "C" tahvel_status tahvel_store(tahvel_agent* agent, const char* rdf, size_t len,
                                      int format, const char* context, int persistent,
                                      uint64_t* item_out) {
  static constexpr const char* fn = "tahvel_store";
  return guarded(fn, [&] {
    clear(item_out);
    if (!registry().contains(agent)) return bad_handle(fn, "agent");
    if (rdf == nullptr && len > 0)
      return set_error(TAHVEL_INVALID_ARGUMENT, fn, "rdf is NULL but len is not 0");
    tahvel::node::ParseOptions options;
    if (format == TAHVEL_FORMAT_NTRIPLES) {
      options.format = tahvel::node::Format::ntriples;
    } else if (format == TAHVEL_FORMAT_TURTLE) {
      options.format = tahvel::node::Format::turtle;
      options.prefixes = agent->prefixes;
    } else {
      return set_error(TAHVEL_INVALID_ARGUMENT, fn,
                       "unknown format " + std::to_string(format) +
                           " (use TAHVEL_FORMAT_NTRIPLES or TAHVEL_FORMAT_TURTLE)");
    }
    auto ctx = parse_context(context);
    if (!ctx) return set_error(fn, ctx.error());
    const std::string_view text(rdf == nullptr ? "" : rdf, len);
    auto triples = tahvel::node::parse_rdf(text, options);
    if (!triples) return set_error(fn, triples.error());
    if (triples->empty())
      return set_error(TAHVEL_INVALID_ARGUMENT, fn, "the input holds no triples");
    tahvel::node::Item item;
    item.triples = std::move(*triples);
    item.context = std::move(*ctx);
    item.persistent = persistent != 0;
    auto stored = agent->agent.store(item);
    if (!stored) return set_error(fn, stored.error());
    if (item_out != nullptr) *item_out = *stored;
    return TAHVEL_OK;
  });
}

namespace {
tahvel_status subscribe_as(const char* fn, tahvel_agent* agent, const char* s, const char* p, const char* o,
                           bool earlier, uint64_t* subscription_out) {
  return guarded(fn, [&] {
    clear(subscription_out);
    if (!registry().contains(agent)) return bad_handle(fn, "agent");
    auto pattern = parse_pattern(s, p, o);
    if (!pattern) return set_error(fn, pattern.error());
    auto subscription = agent->agent.subscribe(*pattern, {.earlier = earlier});
    if (!subscription) return set_error(fn, subscription.error());
    if (subscription_out != nullptr) *subscription_out = *subscription;
    return TAHVEL_OK;
  });
}
}  // namespace

extern "C" tahvel_status tahvel_subscribe(tahvel_agent* agent, const char* s, const char* p,
                                          const char* o, uint64_t* subscription_out) {
  return subscribe_as("tahvel_subscribe", agent, s, p, o, false, subscription_out);
}

extern "C" tahvel_status tahvel_subscribe_earlier(tahvel_agent* agent, const char* s, const char* p,
                                                  const char* o, uint64_t* subscription_out) {
  return subscribe_as("tahvel_subscribe_earlier", agent, s, p, o, true, subscription_out);
}

namespace {
// tahvel_take and tahvel_take_as; `fn` names the one called in errors.
tahvel_status take_as(const char* fn, tahvel_agent* agent, int timeout_ms, int format, uint64_t* item_out,
                      char** text_out, size_t* len_out) {
  return guarded(fn, [&] {
    clear(item_out);
    clear(text_out);
    clear(len_out);
    if (!registry().contains(agent)) return bad_handle(fn, "agent");
    if (format != TAHVEL_FORMAT_NTRIPLES && format != TAHVEL_FORMAT_JSON) return bad_format(fn, format);
    const auto asked = std::chrono::steady_clock::now();
    auto taken = take_waiting(agent->agent, timeout_ms);
    if (!taken) return set_error(fn, taken.error());
    if (!*taken) {
      const auto waited = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - asked);
      if (timeout_ms < 0 || waited.count() < timeout_ms)
        return set_error(TAHVEL_TIMEOUT, fn, "the wait was ended by a signal after " + std::to_string(waited.count()) + " ms");
      return set_error(TAHVEL_TIMEOUT, fn, "no item within " + std::to_string(timeout_ms) + " ms");
    }
    const tahvel::node::Delivery& delivery = **taken;
    tahvel_status status = copy_out(fn, *render(delivery.records, format), text_out, len_out);
    if (status == TAHVEL_OK && item_out != nullptr) *item_out = delivery.item;
    return status;
  });
}
}  // namespace

extern "C" tahvel_status tahvel_take(tahvel_agent* agent, int timeout_ms, uint64_t* item_out,
                                     char** ntriples_out, size_t* len_out) {
  return take_as("tahvel_take", agent, timeout_ms, TAHVEL_FORMAT_NTRIPLES, item_out, ntriples_out, len_out);
}

extern "C" tahvel_status tahvel_take_as(tahvel_agent* agent, int timeout_ms, int format,
                                        uint64_t* item_out, char** text_out, size_t* len_out) {
  return take_as("tahvel_take_as", agent, timeout_ms, format, item_out, text_out, len_out);
}

extern "C" tahvel_status tahvel_pending(tahvel_agent* agent, uint64_t* count_out) {
  static constexpr const char* fn = "tahvel_pending";
  return guarded(fn, [&] {
    clear(count_out);
    if (!registry().contains(agent)) return bad_handle(fn, "agent");
    if (count_out == nullptr) return set_error(TAHVEL_INVALID_ARGUMENT, fn, "count_out must not be NULL");
    auto pending = agent->agent.pending();
    if (!pending) return set_error(fn, pending.error());
    *count_out = *pending;
    return TAHVEL_OK;
  });
}

extern "C" tahvel_status tahvel_unsubscribe(tahvel_agent* agent, uint64_t subscription) {
  static constexpr const char* fn = "tahvel_unsubscribe";
  return guarded(fn, [&] {
    if (!registry().contains(agent)) return bad_handle(fn, "agent");
    auto removed = agent->agent.unsubscribe(subscription);
    if (!removed) return set_error(fn, removed.error());
    return TAHVEL_OK;
  });
}

extern "C" tahvel_status tahvel_ack(tahvel_agent* agent, uint64_t item) {
  static constexpr const char* fn = "tahvel_ack";
  return guarded(fn, [&] {
    if (!registry().contains(agent)) return bad_handle(fn, "agent");
    auto acked = agent->agent.ack(item);
    if (!acked) return set_error(fn, acked.error());
    return TAHVEL_OK;
  });
}

extern "C" void tahvel_install_stop_signal_handlers(void) { tahvel::node::install_stop_signal_handlers(); }

extern "C" int tahvel_stop_signal_received(void) { return tahvel::node::stop_signal_received() ? 1 : 0; }

extern "C" int tahvel_stop_exit_status(void) { return tahvel::node::stop_exit_status(); }
