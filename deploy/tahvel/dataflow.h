// Which agents of a topology would wait for input that nothing in the file gives them: a home
// that runs tahvel-hrv without tahvel-rr, or a gateway without the sensor its rpeak reads, comes
// up, reports nothing wrong and writes no HRV. `tahvel up` says so before it starts anything.
//
// The shipped programs' items are known: tahvel-ecg-source writes recordings and ECG chunks,
// tahvel-rpeak takes the chunks and writes R-peaks, tahvel-rr takes those and writes RR series,
// tahvel-hrv takes those and writes HRV windows, tahvel-trend takes the windows (rpeak, rr and
// hrv also read the recording's description on their board). A node holds what its own agents
// write and what its children's forward policies pass up from what they hold. A program of the
// deployment's own may write anything: a node running one, and every node above it, is taken
// to hold everything its policies pass.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "tahvel/node/node.h"
#include "topology.h"

namespace tahvel::cli {

// A node's forward policy as its uplink will subscribe it; nullopt when it cannot be told (then
// anything may go up).
using ForwardPolicies = std::map<std::string, std::optional<std::vector<node::Pattern>>>;

// One warning per input of an agent of `judged` (ids of `topo`'s nodes) that no agent of its node
// writes and no child passes up, naming where the agent is in the file.
std::vector<std::string> inputs_nothing_gives(const Topology& topo, const ForwardPolicies& policies,
                                              const std::vector<const NodeSpec*>& judged);

}  // namespace tahvel::cli
