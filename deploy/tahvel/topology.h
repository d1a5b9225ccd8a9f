// A deployment's topology file (TOML, docs/deploy.md): nodes, their IRIs, tiers, parents, links,
// stores and agents. Parsed and checked as a whole before anything starts: an error names the
// file, line and column (TOML syntax) or the node and key (meaning).
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "tahvel/agents/supervisor.h"
#include "tahvel/node/error.h"
#include "tahvel/uri/iri.h"

namespace tahvel::cli {

// How a node's children reach it (`listen`) — and so how each child links to it.
struct LinkSpec {
  std::string kind;  // "lcm" or "dds"
  std::string lcm_url = "udpm://239.255.76.67:7667?ttl=0";
  std::uint32_t dds_domain = 0;
  std::string dds_config;  // path of a Cyclone DDS XML file (relative to the topology file)
  std::string url_at;      // where `url` is written ("FILE:LINE:COL"; the table's when absent)
};

struct AgentSpec {
  std::string id;
  std::vector<std::string> run;             // argv; placeholders below
  std::vector<std::string> run_with_mitdb;  // used instead of `run` when TAHVEL_MITDB is set
  agents::Restart restart = agents::Restart::on_failure;
  std::string at;                           // "FILE:LINE:COL" of its table, for errors
};

// A node id's most bytes: the state directory names files after it, the longest being
// supervisor-<id>.apply.lock, and a file name has at most 255 bytes.
inline constexpr std::size_t kMaxNodeIdBytes = uri::kMaxIdBytes;

struct NodeSpec {
  std::string id;
  std::string iri;
  std::string tier;
  std::string parent;                  // parent node id, empty for a root
  std::vector<LinkSpec> listen;        // for its children: at most one per kind
  std::string up;                      // the kind of its parent's `listen` it links over
  std::string up_at;                   // where `up` is written (the node's table when absent)
  std::string durability = "fast";     // fast | durable
  std::uint64_t ring = 0;
  std::vector<std::string> forward;    // uplink policy patterns "S P O" (CURIEs, _ for any)
  bool forward_given = false;          // absent: the default policy; `forward = []`: nothing goes up
  std::string forward_at;              // where `forward` is written (the node's table when absent)
  std::vector<std::string> forward_each_at;  // where each of its patterns is written
  // Where pattern `i` of `forward` is written (FILE:LINE:COL), for errors about that pattern.
  const std::string& forward_place(std::size_t i) const { return i < forward_each_at.size() ? forward_each_at[i] : forward_at; }
  std::vector<std::filesystem::path> load;  // Turtle files put (persistent) into a new store
  std::filesystem::path behaviours;    // the dispatcher's folder of behaviours; empty: none
  std::vector<AgentSpec> agents;
  // Where the file says it ("FILE:LINE:COL"), for errors found once all nodes are read: the
  // node's table, its `parent`, its `iri`, its `load` and its `store` (the table's when the key
  // is absent).
  std::string at, parent_at, iri_at, load_at, store_at;
};

struct Topology {
  std::filesystem::path file;
  std::string name;
  std::vector<NodeSpec> nodes;  // parents before their children

  const NodeSpec* node(const std::string& id) const;
  std::vector<const NodeSpec*> children(const std::string& id) const;
  // The parent's `listen` that `child` links over; null for a root.
  const LinkSpec* uplink(const NodeSpec& child) const;
};

// What agent `id` is on every node `tahvel up` runs ("the node's link (its communication
// agent)"), so that no child node and no topology agent may take it; null for any other id.
const char* agent_id_in_use(const std::string& id);

// Reads and checks FILE: TOML syntax; unique node ids; every parent exists, no cycles; a child's
// IRI is its parent's IRI + "/" + its id (derived when omitted); a parent with children has a
// `listen` (one table, or an array with at most one per kind), and a child whose parent listens
// on several says which with `up`; kinds are lcm or dds; agent ids are valid and unique per node.
node::Result<Topology> load_topology(const std::filesystem::path& file);

// A DDS link without listen.config reads Cyclone's configuration from CYCLONEDDS_URI: for the
// links of the nodes `here` (those brought up on this machine: their own listens and uplinks),
// an error naming the listen when a file the variable names cannot be read (the link would die
// at each restart).
node::Result<void> check_cyclone_uri(const Topology& topo, const std::vector<const NodeSpec*>& here);

// Cyclone DDS gives each process on a host a participant index, up to the config's
// MaxAutoParticipantIndex when ParticipantIndex is "auto" (the shipped loopback file: 50): for
// the nodes `here`, an error naming the listen when more of their links would run on one domain
// than that allows (those past it would fail at every start).
node::Result<void> check_dds_participants(const Topology& topo, const std::vector<const NodeSpec*>& here);

// What an agent's command is expanded with: the environment of the `tahvel up` that asked, not
// the running supervisor's (which may have been started from another shell days before).
struct CommandContext {
  std::filesystem::path bin;  // {bin}: the directory of the tahvel binary that ran `up`
  std::string mitdb;          // {mitdb} and run_with_mitdb: TAHVEL_MITDB ("" when unset)
  std::string path;           // PATH, where a bare program name is looked up
  std::filesystem::path dir;  // {dir}: the directory of the topology file (absolute)
  // This process's: its own binary's directory, TAHVEL_MITDB and PATH.
  static CommandContext of_this_process();
};

// An agent's argv with placeholders expanded: {store} (the node's store directory), {iri} (the
// node IRI), {bin}, {mitdb}, {dir}; a bare program name becomes the path found on the context's
// PATH.
// Errors (invalid_argument, naming node and agent): {mitdb} used while TAHVEL_MITDB is unset
// or not a directory; a program that is not an executable file or not on PATH.
node::Result<std::vector<std::string>> expand_agent_command(const AgentSpec& agent, const NodeSpec& node,
                                                            const std::filesystem::path& store,
                                                            const CommandContext& context);

// The command line of an agent program of this build (tahvel-hrv, tahvel-rpeak, … in
// context.bin), checked by the program itself, run with TAHVEL_CHECK_ARGS=1 (it stops before it
// touches the node): a refused flag ("--window -5") only showed as the agent restarted for ever.
// Errors (invalid_argument): the agent's place, then the program's own message. Other programs,
// and a check that cannot run, pass.
node::Result<void> check_agent_flags(const AgentSpec& agent, const NodeSpec& node, const std::vector<std::string>& argv,
                                     const CommandContext& context);

// A reasoner agent's rule file (`tahvel reason {store} RULES`, argv as expanded), read and parsed
// as the reasoner will at its start, with the node's `prefixes` (its store's, or the standard
// ones for a store not made yet): a missing or broken file only showed as the reasoner failing
// and restarted for ever. Only read, not parsed, when the command gives --prefix or
// --default-ns. Errors (invalid_argument): the agent's place, then the rule file's
// file:line:col and what is wrong.
node::Result<void> check_rule_file(const AgentSpec& agent, const NodeSpec& node, const std::vector<std::string>& argv,
                                   const uri::PrefixMap& prefixes);

}  // namespace tahvel::cli
