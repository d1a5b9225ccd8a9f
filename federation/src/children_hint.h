// What an "unknown node" error adds when no spelling of the name was meant: the children the
// node at that hop knows, so that a path taken from another layout (<…/hospital/home2> where a
// ward lies between) shows where the tree goes on.
#pragma once

#include <algorithm>
#include <string>
#include <vector>

#include "tahvel/node/node.h"

namespace tahvel::federation::detail {

// Whether the board says `iri` made data here, as an agent's IRI is named: a recording's sensor
// (sosa:madeBySensor) or the writer a derived item is attributed to (prov:wasAttributedTo). A
// query --at such an IRI (a recording's prefix taken for a node's) is told to ask the agent's
// node. A child node's IRI is named so by no record of its parent (its state, its agent's
// subscription), so a child that is down or gone is not called an agent. Index lookups that
// stop at the first record.
inline bool made_data(const node::Snapshot& snap, const std::string& iri) {
  for (const char* predicate : {"http://www.w3.org/ns/sosa/madeBySensor", "http://www.w3.org/ns/prov#wasAttributedTo"}) {
    bool found = false;
    const node::Pattern pattern{.p = node::Term::iri(predicate), .o = node::Term::iri(iri)};
    if (snap.for_each(pattern, [&](const node::Record&) { return !(found = true); }) && found) return true;
  }
  return false;
}

// "; its child is <a>", "; its children are <a>, <b> … and N more", or `none` when there is none.
inline std::string children_hint(std::vector<std::string> children, const std::string& none) {
  std::sort(children.begin(), children.end());
  children.erase(std::unique(children.begin(), children.end()), children.end());
  if (children.empty()) return none;
  constexpr std::size_t kShown = 8;
  std::string out = children.size() == 1 ? "; its child is " : "; its children are ";
  for (std::size_t i = 0; i < children.size() && i < kShown; ++i) out += (i ? ", <" : "<") + children[i] + ">";
  if (children.size() > kShown) out += " and " + std::to_string(children.size() - kShown) + " more (tahvel status)";
  return out;
}

}  // namespace tahvel::federation::detail
