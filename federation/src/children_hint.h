// What an "unknown node" error adds when no spelling of the name was meant: the children the
// node at that hop knows, so that a path taken from another layout (<…/hospital/home2> where a
// ward lies between) shows where the tree goes on.
#pragma once

#include <algorithm>
#include <string>
#include <vector>

namespace tahvel::federation::detail {

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
