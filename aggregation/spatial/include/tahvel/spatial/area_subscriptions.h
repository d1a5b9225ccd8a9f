// Area subscriptions on the whiteboard (docs/spatial.md, S9): "readings from the bedroom" rather
// than "readings from mote7". The node routes by triples and sources, not by geometry, so an
// area subscription is kept as two kinds of items:
//
//   declaration, written by (or for) the subscriber, persistent:
//     _:a tv:areaSubscriber <agent> ; tv:area <room> ;            # or a WKT area:
//         tv:area "POLYGON((...))"^^geo:wktLiteral ; tv:areaFloor 1 ;   # floor optional
//         tv:predicate P .                   # tv:subject / tv:object / tv:context likewise
//   expansions, ordinary node subscriptions (R9) written by the node's area keeper (agent
//   `areas`), one per located feature or sensor, each naming its declaration:
//     _:x tv:subscriber <agent> ; tv:predicate P ; tv:source <sensor> ;   # a sensor's readings
//         tv:areaSubscription 42 .
//     _:y tv:subscriber <agent> ; tv:predicate P ; tv:subject <feature> ; tv:areaSubscription 42 .
//
// so the agent receives what `tahvel list --area` selects (S8): records whose subject is a
// feature located in the area, or whose source is a sensor located there (or a writer under
// it). sync_area_subscriptions() reconciles the expansions with the plan: new ones are stored
// before stale ones are removed, so a reading is never missed while a sensor stays in the area.
// Who runs it: `tahvel subscribe --area` once, `tahvel up` whenever the plan or a declaration
// changes (AreaKeeper), and an agent's own AreaSubscription::refresh.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "tahvel/node/node.h"
#include "tahvel/spatial/board.h"
#include "tahvel/spatial/error.h"

namespace tahvel::spatial {

inline constexpr const char* kTvAreaSubscriber = "https://w3id.org/tahvel#areaSubscriber";
inline constexpr const char* kTvArea = "https://w3id.org/tahvel#area";
inline constexpr const char* kTvAreaFloor = "https://w3id.org/tahvel#areaFloor";
inline constexpr const char* kTvAreaSubscription = "https://w3id.org/tahvel#areaSubscription";
// The agent id under which a node's area keeper writes expansions.
inline constexpr const char* kAreaKeeperId = "areas";

// Writes the declaration of `agent`'s subscription to the records matching `pattern` (s, p, o
// and context; other fields must be unset) located in `spec`. Writing the same declaration
// again (a restarted agent) returns the existing one. Returns its item id. Expansions follow at
// the next sync_area_subscriptions. Errors: the store's; a pattern field that cannot be used.
Result<std::uint64_t> declare_area_subscription(const node::Node& node, node::Agent& agent,
                                                const AreaSpec& spec,
                                                const node::Pattern& pattern = {});

struct AreaSyncReport {
  std::size_t declarations = 0;  // declarations on the board
  std::size_t added = 0;         // expansions stored
  std::size_t removed = 0;       // expansions removed (stale, duplicate, or declaration gone)
  // Items put into subscribers' input buffers by the new expansions: those stored after the
  // sensor or feature came into the area and before its expansion was written (S9).
  std::uint64_t caught_up = 0;
  // One line per declaration that could not be expanded (its room is not on the board, its WKT
  // is malformed, ...): it has no expansions until the cause is fixed. Then one per located
  // feature the plan skipped ("feature skipped: <iri>: WKT column ..."): in no area.
  std::vector<std::string> problems;
};

// Reconciles the expansions of every declaration (or only of `declaration`) with the plan on the
// board now, and removes expansions whose declaration is gone. Errors: the store's.
Result<AreaSyncReport> sync_area_subscriptions(node::Node& node,
                                               std::optional<std::uint64_t> declaration = {});

// What one declaration expands to now: sensors (by source) and features (by subject), sorted.
struct AreaExpansion {
  std::vector<std::string> sensors;
  std::vector<std::string> features;
};
Result<AreaExpansion> area_expansion(const node::Snapshot& snapshot, std::uint64_t declaration);

// Keeps a node's area subscriptions current while it runs (`tahvel up` runs one per node):
// poll() syncs when a declaration arrived or, while declarations exist, when a geo:asWKT,
// geo:hasGeometry or tv:floor record was stored or removed, or a declaration was removed.
class AreaKeeper {
 public:
  // Subscribes the keeper agent to new declarations and syncs once; that sync's report goes to
  // `*first` when given. Errors: the store's.
  static Result<AreaKeeper> open(const std::filesystem::path& store_dir, AreaSyncReport* first = nullptr);

  // Waits up to `wait` for a change; returns the sync's report when it synced. A keeper's
  // reports give a problem when it appears: a sync that meets again what the one before it
  // reported leaves it out (moving a sensor syncs, and a skipped feature repeated at every move
  // filled the log); one fixed and come back is given again. A sync that fails returns its
  // error once; it is tried again every second until it succeeds (the same error not returned
  // again meanwhile).
  Result<std::optional<AreaSyncReport>> poll(std::chrono::milliseconds wait = std::chrono::milliseconds(0));

  // Syncs now, whatever changed.
  Result<AreaSyncReport> sync();

  const std::string& iri() const { return node_.iri(); }

 private:
  AreaKeeper(node::Node node, node::Agent agent) : node_(std::move(node)), agent_(std::move(agent)) {}

  node::Node node_;
  node::Agent agent_;
  std::uint64_t bookmark_ = 0;
  std::size_t declarations_ = 0;
  std::set<std::string> told_;  // the problems of the last sync
  std::optional<std::chrono::steady_clock::time_point> retry_at_;  // after a failed sync
  std::string last_failure_;                                       // its message, said once
};

// An agent's own area subscription: declares it, syncs it, and follows the plan when the agent
// calls refresh() (no keeper needed). One object per declaration.
class AreaSubscription {
 public:
  // `node` is borrowed: it must outlive the AreaSubscription.
  // Errors: the store's; the room of `spec` is not on the board (nothing is written then).
  static Result<AreaSubscription> open(node::Node& node, node::Agent& agent, AreaSpec spec,
                                       const node::Pattern& pattern = {});

  // Reads the change stream since the last call (waiting up to `wait` for a change); when the
  // plan changed, re-syncs. Returns true when the set of sensors or features changed.
  Result<bool> refresh(std::chrono::milliseconds wait = std::chrono::milliseconds(0));

  // The sensors whose readings reach the agent now, sorted.
  std::vector<std::string> sensors() const { return expansion_.sensors; }
  // The located features (sensors and rooms) whose records reach the agent by subject, sorted.
  std::vector<std::string> features() const { return expansion_.features; }
  std::uint64_t declaration() const { return declaration_; }

 private:
  AreaSubscription(node::Node& node, std::uint64_t declaration)
      : node_(&node), declaration_(declaration) {}
  Result<bool> sync();

  node::Node* node_;
  std::uint64_t declaration_;
  std::uint64_t bookmark_ = 0;
  AreaExpansion expansion_;
};

}  // namespace tahvel::spatial
