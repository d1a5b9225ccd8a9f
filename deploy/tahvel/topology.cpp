#include "topology.h"

#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>
#include <set>
#include <toml++/toml.h>

#include "tahvel/uri/iri.h"

namespace tahvel::cli {
namespace {

using node::Errc;

std::string where(const toml::node& n, const std::filesystem::path& file) {
  const auto& src = n.source();
  return file.string() + ":" + std::to_string(src.begin.line) + ":" + std::to_string(src.begin.column);
}

node::Result<LinkSpec> link_spec(const toml::table& t, const std::filesystem::path& file, const std::string& node_id) {
  LinkSpec spec;
  auto kind = t["kind"].value<std::string>();
  if (!kind || (*kind != "lcm" && *kind != "dds"))
    return node::fail(Errc::invalid_argument, where(t, file) + ": node '" + node_id + "': listen.kind must be \"lcm\" or \"dds\"");
  spec.kind = *kind;
  if (auto url = t["url"].value<std::string>()) spec.lcm_url = *url;
  if (auto domain = t["domain"].value<std::int64_t>()) {
    if (*domain < 0 || *domain > 232)
      return node::fail(Errc::invalid_argument, where(t, file) + ": node '" + node_id + "': listen.domain must be 0..232");
    spec.dds_domain = static_cast<std::uint32_t>(*domain);
  }
  if (auto config = t["config"].value<std::string>()) {
    std::filesystem::path p = *config;
    if (p.is_relative()) p = file.parent_path() / p;
    spec.dds_config = p.lexically_normal().string();
  }
  return spec;
}

node::Result<std::vector<std::string>> strings(const toml::node* n, const std::filesystem::path& file, const std::string& what) {
  std::vector<std::string> out;
  if (!n) return out;
  const toml::array* array = n->as_array();
  if (!array) return node::fail(Errc::invalid_argument, where(*n, file) + ": " + what + " must be an array of strings");
  for (const auto& e : *array) {
    auto s = e.value<std::string>();
    if (!s) return node::fail(Errc::invalid_argument, where(e, file) + ": " + what + " must be an array of strings");
    out.push_back(*s);
  }
  return out;
}

// `restart` of an agent: "on-failure" (also when absent), "always", "never"; true and false
// (the older spelling) mean "always" and "never".
node::Result<agents::Restart> restart_policy(const toml::node* n, const std::filesystem::path& file,
                                             const std::string& agent_id) {
  if (!n) return agents::Restart::on_failure;
  if (auto b = n->value<bool>(); b && n->is_boolean()) return *b ? agents::Restart::always : agents::Restart::never;
  if (auto text = n->value<std::string>()) {
    for (auto r : {agents::Restart::on_failure, agents::Restart::always, agents::Restart::never})
      if (*text == agents::restart_name(r)) return r;
  }
  return node::fail(Errc::invalid_argument, where(*n, file) + ": agent '" + agent_id +
                                                "': restart must be \"on-failure\", \"always\" or \"never\"");
}

// The UDP port of an LCM `udpm://` URL (LCM's default 7667 when it names none), or nothing for
// another provider.
std::optional<std::uint32_t> lcm_udp_port(const std::string& url) {
  constexpr std::string_view scheme = "udpm://";
  if (!url.starts_with(scheme)) return std::nullopt;
  const std::string address = url.substr(scheme.size(), url.find('?') == std::string::npos ? std::string::npos
                                                                                           : url.find('?') - scheme.size());
  const auto colon = address.rfind(':');
  if (colon == std::string::npos) return 7667;
  char* end = nullptr;
  const unsigned long port = std::strtoul(address.c_str() + colon + 1, &end, 10);
  if (end == address.c_str() + colon + 1 || *end != '\0' || port > 65535) return std::nullopt;
  return static_cast<std::uint32_t>(port);
}

// Cyclone DDS binds its sockets for domain D on ports from 7400 + 250 D (its default port mapping:
// discovery and data, multicast and one unicast pair per participant index, "auto" indices on
// one host counting up from 0) without SO_REUSEADDR. An LCM link whose UDP port falls among them
// fails to bind ("Address already in use") as soon as enough DDS participants run on its host —
// LCM's default 7667 is domain 1's fourth participant — and then fails on every restart while
// that participant lives. Nodes of one file may share a host (`tahvel up FILE` puts all on one),
// so such a file is refused.
constexpr std::uint32_t kDdsPortBase = 7400, kDdsDomainGain = 250;

node::Result<void> check_lcm_ports_clear_of_dds(const Topology& topo) {
  std::map<std::uint32_t, std::string> dds_domains;  // domain -> a node listening on it
  for (const auto& n : topo.nodes)
    if (n.listen && n.listen->kind == "dds") dds_domains.emplace(n.listen->dds_domain, n.id);
  for (const auto& n : topo.nodes) {
    if (!n.listen || n.listen->kind != "lcm") continue;
    const auto port = lcm_udp_port(n.listen->lcm_url);
    if (!port) continue;
    for (const auto& [domain, dds_node] : dds_domains) {
      const std::uint32_t first = kDdsPortBase + kDdsDomainGain * domain, last = first + kDdsDomainGain - 1;
      if (*port < first || *port > last) continue;
      return node::fail(Errc::invalid_argument,
                        topo.file.string() + ": node '" + n.id + "': listen.url " + n.listen->lcm_url + ": UDP port " +
                            std::to_string(*port) + " is among the ports Cyclone DDS takes for domain " +
                            std::to_string(domain) + " (" + std::to_string(first) + "-" + std::to_string(last) +
                            "), which node '" + dds_node + "' listens on; on a host running both, the LCM link " +
                            "would find its port taken. Use a port outside " + std::to_string(first) + "-" +
                            std::to_string(last) + " or another DDS domain");
    }
  }
  return {};
}

}  // namespace

const NodeSpec* Topology::node(const std::string& id) const {
  for (const auto& n : nodes)
    if (n.id == id) return &n;
  return nullptr;
}

std::vector<const NodeSpec*> Topology::children(const std::string& id) const {
  std::vector<const NodeSpec*> out;
  for (const auto& n : nodes)
    if (n.parent == id) out.push_back(&n);
  return out;
}

node::Result<Topology> load_topology(const std::filesystem::path& file) {
  toml::table root;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec)) {
    return node::fail(Errc::not_found, "cannot read topology file " + file.string() + ": " +
                                          (std::filesystem::exists(file, ec) ? "not a regular file" : "no such file"));
  }
  try {
    root = toml::parse_file(file.string());
  } catch (const toml::parse_error& e) {
    return node::fail(Errc::syntax, file.string() + ":" + std::to_string(e.source().begin.line) + ":" +
                                        std::to_string(e.source().begin.column) + ": " + std::string(e.description()));
  }
  Topology topo;
  topo.file = file;
  topo.name = root["deployment"]["name"].value_or(file.stem().string());
  const toml::array* nodes = root["node"].as_array();
  if (!nodes || nodes->empty()) return node::fail(Errc::invalid_argument, file.string() + ": no [[node]] tables");
  std::vector<NodeSpec> specs;
  std::map<std::string, std::size_t> by_id;
  for (const auto& entry : *nodes) {
    const toml::table* t = entry.as_table();
    if (!t) return node::fail(Errc::invalid_argument, where(entry, file) + ": [[node]] must be a table");
    NodeSpec spec;
    auto id = (*t)["id"].value<std::string>();
    if (!id) return node::fail(Errc::invalid_argument, where(*t, file) + ": a node needs an id");
    if (auto ok = uri::check_id(*id); !ok) return node::fail(Errc::invalid_argument, where(*t, file) + ": node id '" + *id + "': " + ok.error().message);
    spec.id = *id;
    if (by_id.count(spec.id)) return node::fail(Errc::invalid_argument, where(*t, file) + ": node id '" + spec.id + "' appears twice");
    spec.iri = (*t)["iri"].value_or(std::string());
    spec.tier = (*t)["tier"].value_or(std::string());
    spec.parent = (*t)["parent"].value_or(std::string());
    if (const toml::table* listen = (*t)["listen"].as_table()) {
      auto l = link_spec(*listen, file, spec.id);
      if (!l) return Unexpected<node::Error>{l.error()};
      spec.listen = *l;
    }
    if (const toml::table* store = (*t)["store"].as_table()) {
      spec.durability = (*store)["durability"].value_or(std::string("fast"));
      if (spec.durability != "fast" && spec.durability != "durable")
        return node::fail(Errc::invalid_argument, where(*store, file) + ": node '" + spec.id + "': store.durability must be \"fast\" or \"durable\"");
      auto ring = (*store)["ring"].value_or(std::int64_t{0});
      if (ring < 0) return node::fail(Errc::invalid_argument, where(*store, file) + ": node '" + spec.id + "': store.ring must be >= 0");
      spec.ring = static_cast<std::uint64_t>(ring);
    }
    auto forward = strings((*t)["forward"].node(), file, "node '" + spec.id + "': forward");
    if (!forward) return Unexpected<node::Error>{forward.error()};
    spec.forward = *forward;
    if (auto behaviours = (*t)["behaviours"].value<std::string>()) {
      std::filesystem::path p = *behaviours;
      if (p.is_relative()) p = file.parent_path() / p;
      spec.behaviours = p.lexically_normal();
    }
    auto load = strings((*t)["load"].node(), file, "node '" + spec.id + "': load");
    if (!load) return Unexpected<node::Error>{load.error()};
    for (const auto& l : *load) {
      std::filesystem::path p = l;
      if (p.is_relative()) p = file.parent_path() / p;
      spec.load.push_back(p.lexically_normal());
    }
    if (const toml::array* agents = (*t)["agent"].as_array()) {
      std::set<std::string> seen;
      for (const auto& a : *agents) {
        const toml::table* at = a.as_table();
        if (!at) return node::fail(Errc::invalid_argument, where(a, file) + ": [[node.agent]] must be a table");
        AgentSpec agent;
        agent.id = (*at)["id"].value_or(std::string());
        if (auto ok = uri::check_id(agent.id); !ok)
          return node::fail(Errc::invalid_argument, where(*at, file) + ": node '" + spec.id + "': agent id '" + agent.id + "': " + ok.error().message);
        if (!seen.insert(agent.id).second || agent.id == "link" || agent.id == "uplink")
          return node::fail(Errc::invalid_argument, where(*at, file) + ": node '" + spec.id + "': agent id '" + agent.id + "' is taken");
        auto run = strings((*at)["run"].node(), file, "agent '" + agent.id + "': run");
        if (!run) return Unexpected<node::Error>{run.error()};
        if (run->empty()) return node::fail(Errc::invalid_argument, where(*at, file) + ": agent '" + agent.id + "' needs run = [command, args...]");
        agent.run = *run;
        auto with_mitdb = strings((*at)["run_with_mitdb"].node(), file, "agent '" + agent.id + "': run_with_mitdb");
        if (!with_mitdb) return Unexpected<node::Error>{with_mitdb.error()};
        agent.run_with_mitdb = *with_mitdb;
        if (auto r = restart_policy((*at)["restart"].node(), file, agent.id); r) agent.restart = *r;
        else return Unexpected<node::Error>{r.error()};
        spec.agents.push_back(std::move(agent));
      }
    }
    by_id[spec.id] = specs.size();
    specs.push_back(std::move(spec));
  }
  // Parents first (the order `up` starts nodes in), IRIs derived and checked on the way.
  std::set<std::string> placed;
  while (topo.nodes.size() < specs.size()) {
    bool progress = false;
    for (auto& spec : specs) {
      if (placed.count(spec.id)) continue;
      if (!spec.parent.empty() && !by_id.count(spec.parent))
        return node::fail(Errc::invalid_argument, file.string() + ": node '" + spec.id + "': parent '" + spec.parent + "' is not a node of this file");
      if (!spec.parent.empty() && !placed.count(spec.parent)) continue;
      if (spec.parent.empty()) {
        if (spec.iri.empty()) return node::fail(Errc::invalid_argument, file.string() + ": root node '" + spec.id + "' needs an iri");
        auto n = uri::normalize(spec.iri);
        if (!n) return node::fail(Errc::invalid_iri, file.string() + ": node '" + spec.id + "': iri: " + n.error().message);
        spec.iri = *n;
      } else {
        const NodeSpec& parent = specs[by_id[spec.parent]];
        if (!parent.listen)
          return node::fail(Errc::invalid_argument, file.string() + ": node '" + parent.id + "' has children but no listen = { kind = ... }");
        auto derived = uri::child_node_iri(parent.iri, spec.id);
        if (!derived) return node::fail(Errc::invalid_iri, file.string() + ": node '" + spec.id + "': " + derived.error().message);
        if (!spec.iri.empty()) {
          auto given = uri::normalize(spec.iri);
          if (!given || *given != *derived)
            return node::fail(Errc::invalid_argument, file.string() + ": node '" + spec.id + "': iri <" + spec.iri +
                                                          "> must be its parent's IRI + \"/" + spec.id + "\" = <" + *derived + ">");
        }
        spec.iri = *derived;
      }
      topo.nodes.push_back(spec);
      placed.insert(spec.id);
      progress = true;
    }
    if (!progress) return node::fail(Errc::invalid_argument, file.string() + ": the parents of the nodes form a cycle");
  }
  if (auto clear = check_lcm_ports_clear_of_dds(topo); !clear) return Unexpected<node::Error>{clear.error()};
  return topo;
}

std::vector<std::string> expand_agent_command(const AgentSpec& agent, const NodeSpec& node,
                                              const std::filesystem::path& store,
                                              const std::filesystem::path& bin) {
  const char* mitdb = std::getenv("TAHVEL_MITDB");
  const bool use_mitdb = mitdb && *mitdb && !agent.run_with_mitdb.empty();
  std::vector<std::string> argv = use_mitdb ? agent.run_with_mitdb : agent.run;
  const std::pair<std::string, std::string> vars[] = {
      {"{store}", store.string()}, {"{iri}", node.iri}, {"{bin}", bin.string()}, {"{mitdb}", mitdb ? mitdb : ""}};
  for (auto& arg : argv) {
    for (const auto& [key, value] : vars) {
      for (std::size_t at = arg.find(key); at != std::string::npos; at = arg.find(key, at + value.size()))
        arg.replace(at, key.size(), value);
    }
  }
  return argv;
}

}  // namespace tahvel::cli
