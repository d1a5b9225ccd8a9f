// Area subscriptions: declarations, their expansion into node subscriptions, and the keeper that
// follows the plan (area_subscriptions.h). Every sync reads one snapshot, computes what each
// declaration should expand to, and writes only the difference: a home's plan changes rarely,
// and a sync with nothing to change writes nothing.
#include "tahvel/spatial/area_subscriptions.h"

#include <algorithm>
#include <charconv>
#include <set>
#include <utility>

#include "tahvel/spatial/wkt.h"
#include "tahvel/uri/iri.h"

namespace tahvel::spatial {

namespace {

using node::Term;

constexpr const char* kTvSubscriber = "https://w3id.org/tahvel#subscriber";
constexpr const char* kTvSubject = "https://w3id.org/tahvel#subject";
constexpr const char* kTvPredicate = "https://w3id.org/tahvel#predicate";
constexpr const char* kTvObject = "https://w3id.org/tahvel#object";
constexpr const char* kTvContext = "https://w3id.org/tahvel#context";
constexpr const char* kTvSource = "https://w3id.org/tahvel#source";

Unexpected<Error> store_error(const node::Error& e) { return fail(e.message); }

std::optional<std::int64_t> parse_integer(const Term& term) {
  if (!term.is_literal()) return std::nullopt;
  const std::string& text = term.value;
  std::int64_t value = 0;
  const char* begin = text.data() + (!text.empty() && text[0] == '+' ? 1 : 0);
  auto [end, ec] = std::from_chars(begin, text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size() || begin == end) return std::nullopt;
  return value;
}

struct Declaration {
  std::uint64_t id = 0;
  std::string agent;
  AreaSpec spec;
  std::string wkt;  // the WKT as written, for a shape area
  node::Pattern pattern;
  std::string problem;  // why it cannot be expanded, empty when it can
};

// A term as a message shows it: <iri>, _:label or "text".
std::string describe(const Term& term) {
  if (term.is_iri()) return "<" + term.value + ">";
  if (term.is_blank()) return "_:" + term.value + " (a blank node)";
  return "\"" + term.value + "\" (a literal)";
}

// The declaration about `subject` among an item's records (an item may hold several, one per
// subject of tv:areaSubscriber).
Declaration parse_declaration(std::uint64_t id, const Term& subject, const std::vector<node::Record>& records) {
  Declaration d;
  d.id = id;
  int areas = 0, subscribers = 0;
  for (const node::Record& r : records) {
    if (r.triple.s != subject) continue;
    const std::string& p = r.triple.p.value;
    const Term& o = r.triple.o;
    if (p == kTvArea) ++areas;
    if (p == kTvAreaSubscriber) ++subscribers;
    if (p == kTvAreaSubscriber) d.agent = o.value;
    else if (p == kTvSubject) d.pattern.s = o;
    else if (p == kTvPredicate) d.pattern.p = o;
    else if (p == kTvObject) d.pattern.o = o;
    else if (p == kTvContext) d.pattern.context = o.value;
    else if (p == kTvArea && o.is_iri()) d.spec.room_iri = o.value;
    else if (p == kTvArea && o.is_literal()) {
      d.wkt = o.value;
      auto shape = parse_shape(o.value);
      if (shape) d.spec.shape = std::move(*shape);
      else d.problem = "tv:area: " + shape.error().message;
    } else if (p == kTvAreaFloor) {
      auto floor = parse_floor(o);
      if (floor) d.spec.floor = *floor;
      else d.problem = "tv:areaFloor '" + o.value + "' is not a whole number within ±1e9";
    }
  }
  // What the expansions would carry: a term the node refuses there (a subscriber written as a
  // string or a blank node) failed the sync of every declaration on the node, not this one.
  for (const node::Record& r : records) {
    if (!d.problem.empty() || r.triple.s != subject) continue;
    const std::string& p = r.triple.p.value;
    const Term& o = r.triple.o;
    const bool iri = o.is_iri() && uri::is_valid(o.value);
    if (p == kTvAreaSubscriber && !iri)
      d.problem = "tv:areaSubscriber " + describe(o) + " is not an agent's IRI (write <http://…/agent-id>)";
    else if ((p == kTvPredicate || p == kTvContext) && !iri)
      d.problem = std::string(p == kTvPredicate ? "tv:predicate " : "tv:context ") + describe(o) + " is not an absolute IRI";
    else if (p == kTvSubject && !iri)
      d.problem = "tv:subject " + describe(o) + " is not an absolute IRI";
  }
  if (d.problem.empty() && subscribers > 1) d.problem = "more than one tv:areaSubscriber";
  if (d.problem.empty() && areas > 1) d.problem = "more than one tv:area";
  if (d.problem.empty() && d.spec.room_iri.empty() && !d.spec.shape) d.problem = "no tv:area";
  if (d.problem.empty() && !d.spec.room_iri.empty() && d.spec.floor)
    d.problem = "tv:areaFloor goes with a WKT tv:area only (a room has its own floor)";
  return d;
}

// Every declaration on the board, by the id of its tv:areaSubscriber record (the item's id for
// one written by declare_area_subscription, whose first record that is).
Result<std::map<std::uint64_t, Declaration>> load_declarations(const node::Snapshot& snapshot) {
  node::Pattern heads;
  heads.p = Term::iri(kTvAreaSubscriber);
  auto found = snapshot.list(heads);
  if (!found) return store_error(found.error());
  std::map<std::uint64_t, Declaration> out;
  std::set<std::pair<std::uint64_t, std::string>> seen;  // (item, subject) already read
  for (const node::Record& head : *found) {
    if (!seen.insert({head.meta.item, head.triple.s.value}).second) continue;
    auto records = snapshot.item(head.meta.item);
    if (!records) continue;  // removed meanwhile
    out.emplace(head.meta.id, parse_declaration(head.meta.id, head.triple.s, *records));
  }
  return out;
}

// An expansion's key: "source <iri>" or "subject <iri>".
using Key = std::pair<bool, std::string>;  // {by_source, iri}

// The expansions on the board: declaration id -> key -> expansion item ids (oldest first).
using Expansions = std::map<std::uint64_t, std::map<Key, std::vector<std::uint64_t>>>;

Result<Expansions> load_expansions(const node::Snapshot& snapshot,
                                   std::optional<std::uint64_t> only) {
  node::Pattern links;
  links.p = Term::iri(kTvAreaSubscription);
  if (only) links.o = Term::integer(static_cast<std::int64_t>(*only));
  auto found = snapshot.list(links);
  if (!found) return store_error(found.error());
  Expansions out;
  for (const node::Record& link : *found) {
    auto declaration = parse_integer(link.triple.o);
    if (!declaration || *declaration <= 0) continue;
    auto records = snapshot.item(link.meta.item);
    if (!records) continue;
    std::optional<Key> key;
    for (const node::Record& r : *records) {
      if (r.triple.p.value == kTvSource) key = Key{true, r.triple.o.value};
      else if (r.triple.p.value == kTvSubject && !key) key = Key{false, r.triple.o.value};
    }
    if (!key) key = Key{false, ""};  // malformed: matches nothing wanted, so it is removed
    out[static_cast<std::uint64_t>(*declaration)][*key].push_back(link.meta.item);
  }
  return out;
}

// What `d` should expand to on `plan`; sets d.problem when it cannot be expanded.
std::set<Key> wanted_keys(const BoardPlan& board, Declaration& d) {
  const Plan& plan = board.plan;
  std::set<Key> keys;
  if (!d.problem.empty()) return keys;
  auto area = resolve_area(board, d.spec);
  if (!area) {
    d.problem = area.error().message;
    return keys;
  }
  for (std::string& sensor : plan.sensors_in(*area)) keys.insert({true, std::move(sensor)});
  for (std::string& feature : features_in(plan, d.spec, *area)) {
    // A declaration naming a subject selects by that subject only.
    if (d.pattern.s && (!d.pattern.s->is_iri() || d.pattern.s->value != feature)) continue;
    keys.insert({false, std::move(feature)});
  }
  return keys;
}

// The record id after which `key` has been in `d`'s area: since the declaration, the key's
// feature standing where it stands, and the declaration's room being drawn as it is. Items stored
// after it that the expansion matches and that were written before the expansion went by the
// expansions then on the board: a reading stored between a sensor's move and the sync.
std::uint64_t missed_since(const BoardPlan& board, const Declaration& d, const Key& key) {
  auto placed = [&](const std::string& feature) -> std::uint64_t {
    auto it = board.placed_by.find(feature);
    return it == board.placed_by.end() ? 0 : it->second;
  };
  std::uint64_t since = std::max(d.id, placed(key.second));
  if (!d.spec.room_iri.empty()) since = std::max(since, placed(d.spec.room_iri));
  return since;
}

node::Item expansion_item(const Declaration& d, const Key& key) {
  const Term x = Term::blank("x");
  node::Item item;
  item.persistent = true;
  item.add(x, Term::iri(kTvSubscriber), Term::iri(d.agent));
  if (key.first) {
    if (d.pattern.s) item.add(x, Term::iri(kTvSubject), *d.pattern.s);
    item.add(x, Term::iri(kTvSource), Term::iri(key.second));
  } else {
    item.add(x, Term::iri(kTvSubject), Term::iri(key.second));
  }
  if (d.pattern.p) item.add(x, Term::iri(kTvPredicate), *d.pattern.p);
  if (d.pattern.o) item.add(x, Term::iri(kTvObject), *d.pattern.o);
  if (d.pattern.context) item.add(x, Term::iri(kTvContext), Term::iri(*d.pattern.context));
  item.add(x, Term::iri(kTvAreaSubscription), Term::integer(static_cast<std::int64_t>(d.id)));
  return item;
}

// The node refused the item itself (a term, a pattern), not for the store's state.
bool refused_item(const node::Error& e) {
  return e.code == node::Errc::invalid_argument || e.code == node::Errc::invalid_iri ||
         e.code == node::Errc::syntax || e.code == node::Errc::literal_too_large;
}

bool same_term(const std::optional<Term>& a, const std::optional<Term>& b) {
  if (!a || !b) return !a && !b;
  return a->kind == b->kind && a->value == b->value && a->datatype == b->datatype &&
         a->language == b->language;
}

}  // namespace

Result<std::uint64_t> declare_area_subscription(const node::Node& node, node::Agent& agent,
                                                const AreaSpec& spec,
                                                const node::Pattern& pattern) {
  if (pattern.source || pattern.under || pattern.since || pattern.until || pattern.after_id)
    return fail("an area subscription's pattern takes subject, predicate, object and context only");
  if (spec.room_iri.empty() && !spec.shape) return fail("an area needs a room IRI or a shape");
  Declaration wanted;
  wanted.agent = agent.iri();
  wanted.spec = spec;
  wanted.pattern = pattern;
  if (spec.room_iri.empty()) wanted.wkt = to_wkt(*spec.shape);

  // A restarted agent declares again: the one it has stands. (Two processes declaring the same
  // at once may both write; each declaration then has its expansions, and the agent still gets
  // each item once: input buffers hold an item once.)
  auto snapshot = node.snapshot();
  if (!snapshot) return store_error(snapshot.error());
  auto existing = load_declarations(*snapshot);
  if (!existing) return unexpected(existing.error());
  for (const auto& [id, d] : *existing) {
    if (d.agent != wanted.agent || d.spec.room_iri != spec.room_iri) continue;
    if (spec.room_iri.empty() && (d.wkt != wanted.wkt || d.spec.floor != spec.floor)) continue;
    if (same_term(d.pattern.s, pattern.s) && same_term(d.pattern.p, pattern.p) &&
        same_term(d.pattern.o, pattern.o) && d.pattern.context == pattern.context)
      return id;
  }

  const Term a = Term::blank("a");
  node::Item item;
  item.persistent = true;
  item.add(a, Term::iri(kTvAreaSubscriber), Term::iri(agent.iri()));
  if (!spec.room_iri.empty()) {
    item.add(a, Term::iri(kTvArea), Term::iri(spec.room_iri));
  } else {
    item.add(a, Term::iri(kTvArea), Term::literal(wanted.wkt, kGeoWktLiteral));
    if (spec.floor) item.add(a, Term::iri(kTvAreaFloor), Term::integer(*spec.floor));
  }
  if (pattern.s) item.add(a, Term::iri(kTvSubject), *pattern.s);
  if (pattern.p) item.add(a, Term::iri(kTvPredicate), *pattern.p);
  if (pattern.o) item.add(a, Term::iri(kTvObject), *pattern.o);
  if (pattern.context) item.add(a, Term::iri(kTvContext), Term::iri(*pattern.context));
  auto id = agent.store(item);
  if (!id) return store_error(id.error());
  return *id;
}

Result<AreaSyncReport> sync_area_subscriptions(node::Node& node,
                                               std::optional<std::uint64_t> declaration) {
  auto snapshot = node.snapshot();
  if (!snapshot) return store_error(snapshot.error());
  auto board = load_plan(*snapshot);
  if (!board) return unexpected(board.error());
  auto declarations = load_declarations(*snapshot);
  if (!declarations) return unexpected(declarations.error());
  auto expansions = load_expansions(*snapshot, declaration);
  if (!expansions) return unexpected(expansions.error());

  AreaSyncReport report;
  report.declarations = declarations->size();
  std::vector<node::Item> to_add;
  std::vector<std::pair<std::uint64_t, std::string>> added_for;  // to_add[i]'s declaration and agent
  std::vector<std::uint64_t> in_force_after;                      // to_add[i]: missed_since
  std::vector<std::uint64_t> to_remove;
  for (auto& [id, d] : *declarations) {
    if (declaration && id != *declaration) continue;
    const std::set<Key> wanted = wanted_keys(*board, d);
    if (!d.problem.empty()) report.problems.push_back("area subscription " + std::to_string(id) + " of <" + d.agent + ">: " + d.problem);
    auto& have = (*expansions)[id];
    for (const Key& key : wanted)
      if (!have.count(key)) {
        to_add.push_back(expansion_item(d, key));
        added_for.emplace_back(id, d.agent);
        in_force_after.push_back(missed_since(*board, d, key));
      }
    for (const auto& [key, ids] : have) {
      // Stale keys go whole; a key written twice (two syncs at once) keeps its oldest.
      auto first_kept = wanted.count(key) ? ids.begin() + 1 : ids.begin();
      to_remove.insert(to_remove.end(), first_kept, ids.end());
    }
  }
  for (const auto& [id, have] : *expansions) {
    if (declarations->count(id)) continue;  // the declaration was removed: its expansions go
    for (const auto& [key, ids] : have) to_remove.insert(to_remove.end(), ids.begin(), ids.end());
  }

  // New expansions first, in one transaction with what they missed (before the stale ones go,
  // so that an item those routed to the same agent is not delivered again), then the stale
  // ones: a sensor that stays in the area is covered at every moment.
  if (!to_add.empty()) {
    auto keeper = node.agent(kAreaKeeperId);
    if (!keeper) return store_error(keeper.error());
    auto stored = keeper->store_subscriptions(to_add, in_force_after);
    if (stored) {
      report.added = stored->ids.size();
      report.caught_up = stored->caught_up;
    } else if (refused_item(stored.error())) {
      // One declaration's expansion the node will not take (what parse_declaration does not
      // foresee) must not hold up the others': each alone, the refused ones said.
      // Older than this sync's expansions is older than the first stored: one stored before
      // another in this loop must not count as routing what the other missed.
      std::uint64_t first_of_sync = 0;
      for (std::size_t i = 0; i < to_add.size(); ++i) {
        auto one = keeper->store_subscriptions({to_add[i]}, std::span(&in_force_after[i], 1), first_of_sync);
        if (one) {
          ++report.added, report.caught_up += one->caught_up;
          if (first_of_sync == 0) first_of_sync = one->ids.front();
        } else if (refused_item(one.error())) {
          report.problems.push_back("area subscription " + std::to_string(added_for[i].first) + " of <" +
                                    added_for[i].second + ">: its expansion was refused: " + one.error().message);
        } else {
          return store_error(one.error());
        }
      }
    } else {
      return store_error(stored.error());
    }
  }
  for (std::uint64_t id : to_remove) {
    auto removed = node.remove_item(id);
    if (removed) ++report.removed;
    else if (removed.error().code != node::Errc::not_found) return store_error(removed.error());
  }
  for (const std::string& problem : board->problems) report.problems.push_back("feature skipped: " + problem);
  return report;
}

Result<AreaExpansion> area_expansion(const node::Snapshot& snapshot, std::uint64_t declaration) {
  auto expansions = load_expansions(snapshot, declaration);
  if (!expansions) return unexpected(expansions.error());
  AreaExpansion out;
  for (const auto& [key, ids] : (*expansions)[declaration])
    (key.first ? out.sensors : out.features).push_back(key.second);
  return out;  // sorted: the map's keys are
}

// ---------------------------------------------------------------------------------------------

namespace {

bool changes_the_plan(const node::Change& change) {
  // It may have: the plan is read again. Not for records reclaimed before they were read (a ring
  // under live ECG said so at every poll): a plan's geometry is persistent, never reclaimed.
  if (!change.unreadable.empty()) return !change.reclaimed;
  const std::string& p = change.record.triple.p.value;
  if (p == kGeoAsWkt || p == kGeoHasGeometry || p == kTvFloor) return true;
  // A declaration removed: its expansions go. (A new one arrives through the keeper's input
  // buffer, or here when the keeper watches.)
  return p == kTvAreaSubscriber;
}

}  // namespace

Result<AreaKeeper> AreaKeeper::open(const std::filesystem::path& store_dir, AreaSyncReport* first) {
  auto node = node::Node::open(store_dir);
  if (!node) return store_error(node.error());
  auto agent = node->agent(kAreaKeeperId);
  if (!agent) return store_error(agent.error());
  node::Pattern declarations;
  declarations.p = Term::iri(kTvAreaSubscriber);
  if (auto s = agent->subscribe(declarations); !s) return store_error(s.error());
  AreaKeeper keeper(std::move(*node), std::move(*agent));
  auto synced = keeper.sync();
  if (!synced) return unexpected(synced.error());
  if (first) *first = std::move(*synced);
  return keeper;
}

Result<AreaSyncReport> AreaKeeper::sync() {
  // Declarations already in the input buffer are covered by this sync.
  while (true) {
    auto taken = agent_.take(std::chrono::milliseconds(0));
    if (!taken) return store_error(taken.error());
    if (!*taken) break;
  }
  auto snapshot = node_.snapshot();
  if (!snapshot) return store_error(snapshot.error());
  const std::uint64_t seen = snapshot->last_seq();
  auto report = sync_area_subscriptions(node_);
  if (!report) return report;
  declarations_ = report->declarations;
  bookmark_ = std::max(bookmark_, seen);
  // Said when it appears: a problem the previous sync reported is left out, one that went away
  // and came back is said again.
  std::set<std::string> now(report->problems.begin(), report->problems.end());
  std::erase_if(report->problems, [&](const std::string& problem) { return told_.count(problem) > 0; });
  told_ = std::move(now);
  return report;
}

Result<std::optional<AreaSyncReport>> AreaKeeper::poll(std::chrono::milliseconds wait) {
  bool dirty = false;
  if (declarations_ == 0) {
    // Nothing to keep: sleep on the input buffer, which only new declarations reach. The change
    // stream (every record of the node) is read only while there is something to keep current.
    auto taken = agent_.take(wait);
    if (!taken) return store_error(taken.error());
    dirty = taken->has_value();
  } else {
    auto changes = node_.watch(bookmark_, wait);
    if (!changes) return store_error(changes.error());
    if (!changes->empty()) bookmark_ = changes->back().seq;
    for (const node::Change& change : *changes) dirty = dirty || changes_the_plan(change);
  }
  // A sync that failed (the store full, say) is tried again at the next poll a second later,
  // the plan change that called for it being behind the bookmark by then; the same failure is
  // said once, not at every try.
  const auto now = std::chrono::steady_clock::now();
  if (!dirty && (!retry_at_ || now < *retry_at_)) return std::optional<AreaSyncReport>{};
  auto report = sync();
  if (!report) {
    retry_at_ = now + std::chrono::seconds(1);
    if (report.error().message == last_failure_) return std::optional<AreaSyncReport>{};
    last_failure_ = report.error().message;
    return unexpected(report.error());
  }
  retry_at_.reset();
  last_failure_.clear();
  return std::optional<AreaSyncReport>{std::move(*report)};
}

// ---------------------------------------------------------------------------------------------

Result<AreaSubscription> AreaSubscription::open(node::Node& node, node::Agent& agent,
                                                AreaSpec spec, const node::Pattern& pattern) {
  {
    auto snapshot = node.snapshot();
    if (!snapshot) return store_error(snapshot.error());
    auto board = load_plan(*snapshot);
    if (!board) return unexpected(board.error());
    if (auto area = resolve_area(*board, spec); !area) return unexpected(area.error());
  }
  auto declaration = declare_area_subscription(node, agent, spec, pattern);
  if (!declaration) return unexpected(declaration.error());
  AreaSubscription subscription(node, *declaration);
  if (auto synced = subscription.sync(); !synced) return unexpected(synced.error());
  return subscription;
}

Result<bool> AreaSubscription::refresh(std::chrono::milliseconds wait) {
  auto changes = node_->watch(bookmark_, wait);
  if (!changes) return store_error(changes.error());
  if (changes->empty()) return false;
  bookmark_ = changes->back().seq;
  for (const node::Change& change : *changes) {
    const std::string& p = change.record.triple.p.value;
    if (p == kGeoAsWkt || p == kGeoHasGeometry || p == kTvFloor) return sync();
  }
  return false;
}

Result<bool> AreaSubscription::sync() {
  auto before = node_->snapshot();
  if (!before) return store_error(before.error());
  bookmark_ = std::max(bookmark_, before->last_seq());
  auto report = sync_area_subscriptions(*node_, declaration_);
  if (!report) return unexpected(report.error());
  auto after = node_->snapshot();
  if (!after) return store_error(after.error());
  auto expansion = area_expansion(*after, declaration_);
  if (!expansion) return unexpected(expansion.error());
  bool changed = expansion->sensors != expansion_.sensors || expansion->features != expansion_.features;
  expansion_ = std::move(*expansion);
  return changed;
}

}  // namespace tahvel::spatial
