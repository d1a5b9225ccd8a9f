#include <algorithm>

#include "tahvel/node/node.h"
#include "tahvel/uri/spelling.h"

namespace tahvel::node {

namespace {

// The part of an IRI after its last '#' or '/': what a slip of the prefix leaves the same.
std::string_view local_part(std::string_view iri) {
  const std::size_t cut = iri.find_last_of("#/");
  return cut == std::string_view::npos ? iri : iri.substr(cut + 1);
}

}  // namespace

PredicateMatch match_predicate(std::string_view asked, const std::vector<PredicateSummary>& held, std::size_t edits_below) {
  PredicateMatch match;
  std::size_t nearest_edits = edits_below;
  const std::string_view local = local_part(asked);
  for (const PredicateSummary& h : held) {
    if (h.records == 0) continue;
    if (h.predicate == asked) return {.held = true, .nearest = nullptr};
    const std::string_view held_local = local_part(h.predicate);
    const bool same_namespace = asked.substr(0, asked.size() - local.size()) ==
                                std::string_view(h.predicate).substr(0, h.predicate.size() - held_local.size());
    const std::size_t e = std::min(uri::edit_distance(asked, h.predicate),
                                   uri::edit_distance(local, held_local) + (same_namespace ? 0 : 1));
    if (e < nearest_edits) nearest_edits = e, match.nearest = &h, match.as_near.clear();
    else if (e == nearest_edits && match.nearest) match.as_near.push_back(&h);
  }
  return match;
}

}  // namespace tahvel::node
