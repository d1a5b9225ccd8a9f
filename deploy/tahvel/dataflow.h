// Which agents of a topology would wait for input that nothing in the file gives them, or write
// what a child already sends up: a home that runs tahvel-hrv without tahvel-rr, or a gateway
// without the sensor its rpeak reads, comes up, reports nothing wrong and writes no HRV; a
// hospital that computes HRV from RR intervals a home forwards along with the home's own windows
// holds two windows under each name. `tahvel up` says so before it starts anything.
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

// Warnings about the agents of `judged`, each naming where the agent is in the file:
// - an input that no agent of its node writes and no child passes up (once per cause; the agents
//   that wait on it are named with it);
// - a stage whose input and results both come up from one child, so that the child's stage and
//   this one write one recording's items under the same names.
// A program is known by its `run` (an agent's run_with_mitdb runs the same program on a record).
std::vector<std::string> dataflow_warnings(const Topology& topo, const ForwardPolicies& policies,
                                           const std::vector<const NodeSpec*>& judged);

// Why two agents of `spec` cannot both run, or nullopt: two shipped programs that run as one agent
// (each its --agent, or its program's default), where one process at a time holds an agent (its
// lock), so that the second would fail at each start while the first runs (two ECG sources left
// at their default: a second patient's ECG unmonitored). Other programs are not judged: what
// they run as is not known here. `with_mitdb` as above.
std::optional<std::string> agents_running_as_one(const NodeSpec& spec, bool with_mitdb);

}  // namespace tahvel::cli
