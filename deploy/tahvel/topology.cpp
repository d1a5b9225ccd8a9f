#include "topology.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <optional>
#include <regex>
#include <set>
#include <toml++/toml.h>

#include "tahvel/agents/dispatcher.h"
#include "tahvel/agents/rules.h"
#include "tahvel/aggregation/wfdb.h"
#include "tahvel/federation/transport.h"
#include "tahvel/spatial/area_subscriptions.h"
#include "tahvel/uri/iri.h"
#include "tahvel/uri/spelling.h"

namespace tahvel::cli {
namespace {

using node::Errc;

std::string where(const toml::source_region& src, const std::filesystem::path& file) {
  return file.string() + ":" + std::to_string(src.begin.line) + ":" + std::to_string(src.begin.column);
}
std::string where(const toml::node& n, const std::filesystem::path& file) { return where(n.source(), file); }

std::optional<std::uint32_t> lcm_udp_port(const std::string& url);

// `value` in double quotes for an error message, its control characters as \xNN: the message
// stays on one line whatever the file held.
std::string in_quotes(std::string_view value) {
  std::string out = "\"";
  for (char c : value) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f || c == '"' || c == '\\') {
      char escaped[8];
      std::snprintf(escaped, sizeof escaped, "\\x%02X", static_cast<unsigned char>(c));
      out += escaped;
    } else {
      out += c;
    }
  }
  return out + "\"";
}

// A misspelt key would otherwise be skipped and its default used (`durabilty = "durable"` a fast
// store), so every table accepts only the keys it knows.
// `what` names the node ("node 'h': "), `table` the table's path within it ("store.").
node::Result<void> only_keys(const toml::table& t, std::initializer_list<std::string_view> known,
                             const std::filesystem::path& file, const std::string& what, const std::string& table = "") {
  for (const auto& [key, value] : t) {
    if (std::find(known.begin(), known.end(), key.str()) != known.end()) continue;
    std::string list;
    for (auto k : known) list += (list.empty() ? "" : ", ") + std::string(k);
    // At the key, not its value: the key is what is wrong.
    return node::fail(Errc::invalid_argument, where(key.source(), file) + ": " + what + "unknown key '" + table + std::string(key.str()) +
                                                  "' (known here: " + list + ")");
  }
  return {};
}

// `key` of `t`: nothing when absent, its value when it has type T, else an error naming the key.
template <class T>
node::Result<std::optional<T>> typed(const toml::table& t, std::string_view key, const std::filesystem::path& file,
                                     const std::string& what, std::string_view wanted) {
  const toml::node* n = t.get(key);
  if (!n) return std::optional<T>{};
  auto v = n->value_exact<T>();
  if (!v) return node::fail(Errc::invalid_argument, where(*n, file) + ": " + what + std::string(key) + " must be " + std::string(wanted));
  return std::optional<T>{std::move(*v)};
}

// `key` of `t` as a table, nothing when absent.
node::Result<const toml::table*> table_at(const toml::table& t, std::string_view key, const std::filesystem::path& file,
                                          const std::string& what) {
  const toml::node* n = t.get(key);
  if (!n) return nullptr;
  if (!n->is_table())
    return node::fail(Errc::invalid_argument, where(*n, file) + ": " + what + std::string(key) + " must be a table { ... }");
  return n->as_table();
}

#define TAHVEL_TRY(var, expr)                                      \
  auto var##_result = (expr);                                      \
  if (!var##_result) return Unexpected<node::Error>{var##_result.error()}; \
  auto var = std::move(*var##_result)

// A DDS link without listen.config takes Cyclone's configuration from CYCLONEDDS_URI: a file
// it names that cannot be read is a link that dies at each restart. The first such file, or
// nullopt. The variable is a comma-separated list of files (`file://` optional) and inline XML
// (from '<', which may hold commas: not looked into).
std::optional<std::string> unreadable_cyclone_uri_file() {
  const char* uri = std::getenv("CYCLONEDDS_URI");
  if (!uri) return std::nullopt;
  std::string_view rest(uri);
  while (!rest.empty()) {
    // Cyclone skips blanks and commas before each item (q_config.c); a blank after a name is
    // part of it.
    if (rest.front() == ',' || rest.front() == ' ' || rest.front() == '\t' || rest.front() == '\n' || rest.front() == '\r') {
      rest.remove_prefix(1);
      continue;
    }
    if (const auto first = rest.find_first_not_of(" \t\n\r"); first != std::string_view::npos && rest[first] == '<') break;
    const std::string_view part = rest.substr(0, rest.find(','));
    rest.remove_prefix(part.size());
    std::string path(part);
    if (path.starts_with("file://")) path.erase(0, 7);
    std::error_code ec;
    // A FIFO would block the open: only a regular file is opened.
    if (!std::filesystem::is_regular_file(path, ec) || !std::ifstream(path)) return std::string(part);
  }
  return std::nullopt;
}

node::Result<LinkSpec> link_spec(const toml::table& t, const std::filesystem::path& file, const std::string& node_id) {
  const std::string what = "node '" + node_id + "': listen.";
  if (auto ok = only_keys(t, {"kind", "url", "domain", "config"}, file, "node '" + node_id + "': ", "listen."); !ok)
    return Unexpected<node::Error>{ok.error()};
  LinkSpec spec;
  TAHVEL_TRY(kind, typed<std::string>(t, "kind", file, what, "\"lcm\" or \"dds\""));
  if (!kind)
    return node::fail(Errc::invalid_argument, where(t, file) + ": " + what + "kind is missing: write kind = \"lcm\" or \"dds\"");
  if (*kind != "lcm" && *kind != "dds")
    return node::fail(Errc::invalid_argument, where(*t.get("kind"), file) + ": " + what + "kind is " + in_quotes(*kind) +
                                                  ": it must be \"lcm\" or \"dds\"");
  spec.kind = *kind;
  TAHVEL_TRY(url, typed<std::string>(t, "url", file, what, "a string (an LCM URL such as \"udpm://239.255.76.67:7667?ttl=0\")"));
  TAHVEL_TRY(domain, typed<std::int64_t>(t, "domain", file, what, "an integer 0..232"));
  TAHVEL_TRY(config, typed<std::string>(t, "config", file, what, "a string (a Cyclone DDS XML file)"));
  if (spec.kind == "lcm" && (domain || config))
    return node::fail(Errc::invalid_argument, where(t, file) + ": " + what + "domain and config are for kind = \"dds\"");
  if (spec.kind == "dds" && url)
    return node::fail(Errc::invalid_argument, where(t, file) + ": " + what + "url is for kind = \"lcm\"");
  spec.url_at = where(t.get("url") ? *t.get("url") : static_cast<const toml::node&>(t), file);
  if (url) {
    // Checked here, not when the link first runs: a bad URL there is a link that dies at each
    // restart. A link takes the URL's port and the next (LcmEnd).
    if (auto ok = federation::lcm_down_url(*url); !ok)
      return node::fail(Errc::invalid_argument, where(*t.get("url"), file) + ": " + what + "url: " + ok.error().message);
    spec.lcm_url = *url;
  }
  if (domain) {
    if (*domain < 0 || *domain > 232)
      return node::fail(Errc::invalid_argument, where(*t.get("domain"), file) + ": " + what + "domain must be 0..232");
    spec.dds_domain = static_cast<std::uint32_t>(*domain);
  }
  if (config) {
    std::filesystem::path p = *config;
    if (p.is_relative()) p = std::filesystem::absolute(file).parent_path() / p;
    std::error_code ec;
    std::ifstream in;
    if (std::filesystem::is_regular_file(p, ec)) in.open(p, std::ios::binary);  // not a FIFO, which would block
    if (!in.is_open() || !in)
      return node::fail(Errc::not_found, where(*t.get("config"), file) + ": " + what + "config: cannot read " +
                                             p.lexically_normal().string());
    const std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (auto ok = federation::check_dds_config(xml); !ok)
      return node::fail(Errc::invalid_argument, where(*t.get("config"), file) + ": " + what + "config " +
                                                    p.lexically_normal().string() + ": " + ok.error().message);
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
// (the older spelling) mean "always" and "never". `agent` names it: "node 'home1': agent 'hrv'".
node::Result<agents::Restart> restart_policy(const toml::node* n, const std::filesystem::path& file,
                                             const std::string& agent) {
  if (!n) return agents::Restart::on_failure;
  if (auto b = n->value<bool>(); b && n->is_boolean()) return *b ? agents::Restart::always : agents::Restart::never;
  if (auto text = n->value<std::string>()) {
    for (auto r : {agents::Restart::on_failure, agents::Restart::always, agents::Restart::never})
      if (*text == agents::restart_name(r)) return r;
  }
  return node::fail(Errc::invalid_argument, where(*n, file) + ": " + agent +
                                                ": restart must be \"on-failure\", \"always\" or \"never\" (or true or false, the older "
                                                "spelling of \"always\" and \"never\")");
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

// At most `bytes` of `text`, not cutting a UTF-8 character in two (for messages).
std::string utf8_prefix(const std::string& text, std::size_t bytes) {
  if (text.size() <= bytes) return text;
  while (bytes > 0 && (static_cast<unsigned char>(text[bytes]) & 0xC0) == 0x80) --bytes;
  return text.substr(0, bytes);
}

// A node's link runs its DDS end up to the parent and its DDS end down to its children in one
// process, and Cyclone DDS runs one configuration per domain in a process: a node that listens
// on its parent's domain under another configuration had a link that failed at every start
// ("DDS domain 4 already runs in this process with another configuration"). The files are
// compared by content (two copies of one file are one configuration); an uplink without a file
// takes Cyclone's CYCLONEDDS_URI, which may or may not be the listen's.
node::Result<void> check_one_dds_configuration_per_domain(const Topology& topo) {
  auto text_of = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  };
  auto named = [](const LinkSpec& l) { return l.dds_config.empty() ? std::string("no config (CYCLONEDDS_URI)") : "config " + l.dds_config; };
  for (const auto& n : topo.nodes) {
    const LinkSpec* up = topo.uplink(n);
    if (!up || up->kind != "dds") continue;
    for (const LinkSpec& l : n.listen) {
      if (l.kind != "dds" || l.dds_domain != up->dds_domain) continue;
      // A listen without config on the uplink's domain takes the uplink's (the link opens one
      // endpoint for both); an uplink without one, beside a listen with one, does not.
      if (l.dds_config.empty()) continue;
      if (up->dds_config.empty() || (l.dds_config != up->dds_config && text_of(l.dds_config) != text_of(up->dds_config)))
        return node::fail(Errc::invalid_argument,
                          l.url_at + ": node '" + n.id + "': listens on DDS domain " + std::to_string(l.dds_domain) + " with " +
                              named(l) + ", and its link up to '" + n.parent + "' is on domain " +
                              std::to_string(up->dds_domain) + " with " + named(*up) +
                              ": one link process runs one Cyclone DDS configuration per domain, so this node's link "
                              "would fail at every start; give both the same config, or listen on another domain");
    }
  }
  return {};
}

node::Result<void> check_lcm_ports_clear_of_dds(const Topology& topo) {
  std::map<std::uint32_t, std::string> dds_domains;  // domain -> a node listening on it
  for (const auto& n : topo.nodes)
    for (const auto& l : n.listen)
      if (l.kind == "dds") dds_domains.emplace(l.dds_domain, n.id);
  for (const auto& n : topo.nodes) {
    auto lcm = std::find_if(n.listen.begin(), n.listen.end(), [](const LinkSpec& l) { return l.kind == "lcm"; });
    if (lcm == n.listen.end()) continue;
    const auto up_port = lcm_udp_port(lcm->lcm_url);
    if (!up_port) continue;
    for (const auto& [domain, dds_node] : dds_domains) {
      const std::uint32_t first = kDdsPortBase + kDdsDomainGain * domain, last = first + kDdsDomainGain - 1;
      // The link's frames down take the port after the URL's (LcmEnd).
      const std::uint32_t port = *up_port >= first && *up_port <= last ? *up_port : *up_port + 1;
      if (port < first || port > last) continue;
      return node::fail(Errc::invalid_argument,
                        lcm->url_at + ": node '" + n.id + "': listen.url " + lcm->lcm_url + ": UDP port " +
                            std::to_string(port) + (port == *up_port ? "" : " (the link's port for frames down)") +
                            " is among the ports Cyclone DDS takes for domain " +
                            std::to_string(domain) + " (" + std::to_string(first) + "-" + std::to_string(last) +
                            "), which node '" + dds_node + "' listens on; on a host running both, the LCM link " +
                            "would find its port taken. Use a port outside " + std::to_string(first) + "-" +
                            std::to_string(last) + " or another DDS domain");
    }
  }
  return {};
}

// "a -> b -> a" for the cycle of `path` (parents followed from path[0]) that starts at `at`.
std::string describe_cycle(const std::vector<std::string>& path, const std::string& at) {
  std::string text;
  for (auto it = std::find(path.begin(), path.end(), at); it != path.end(); ++it) text += *it + " -> ";
  return text + at;
}

}  // namespace

// Whose agent `id` is on every node `tahvel up` runs (so no child node may have it), or null.
const char* agent_id_in_use(const std::string& id) {
  if (id == "link" || id == "uplink") return "the node's link (its communication agent)";
  if (id == "supervisor") return "the supervisor, which replaces what it wrote every few seconds";
  if (id == "deploy") return "the one `up` loads files as";
  if (id == "cli") return "the one `tahvel put` and `tahvel load` write as";
  if (id.starts_with("query-")) return "one of `tahvel query`'s";
  // The area keeper and the dispatcher take every item in their input buffers, which on the
  // parent are a child's down queue: configuration for such a child would be eaten.
  if (id == spatial::kAreaKeeperId) return "the node's area keeper, which takes every item addressed to it";
  if (id == agents::DispatcherOptions{}.agent_id) return "the node's dispatcher, which takes every item addressed to it";
  return nullptr;
}

const LinkSpec* Topology::uplink(const NodeSpec& child) const {
  const NodeSpec* parent = node(child.parent);
  if (!parent) return nullptr;
  for (const auto& l : parent->listen)
    if (l.kind == child.up) return &l;
  return nullptr;
}

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

namespace {

// " (in the [[node]] of line 12, id 'home1')" for the node table holding line `line` of `file`,
// as every other error names its node; "" outside one. For the parser's own errors (a key
// given twice), which name only where.
std::string node_table_around(const std::filesystem::path& file, std::size_t line) {
  std::ifstream in(file);
  std::vector<std::string> lines;
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  const auto trimmed = [](const std::string& l) {
    const std::size_t first = l.find_first_not_of(" \t");
    return first == std::string::npos ? std::string() : l.substr(first);
  };
  std::size_t header = lines.size();
  for (std::size_t i = std::min(line, lines.size()); i-- > 0;) {
    const std::string t = trimmed(lines[i]);
    if (t.starts_with("[[node]]")) {
      header = i;
      break;
    }
    if (t.starts_with("[") && !t.starts_with("[[node.") && !t.starts_with("[node.")) return {};  // another table
  }
  if (header == lines.size()) return {};
  std::string id;
  for (std::size_t i = header + 1; i < lines.size(); ++i) {
    const std::string t = trimmed(lines[i]);
    if (t.starts_with("[")) break;  // the node's own keys come before its sub-tables
    static const std::regex id_line(R"re(^id\s*=\s*"([^"]*)")re");
    std::smatch m;
    if (std::regex_search(t, m, id_line)) {
      id = m[1];
      break;
    }
  }
  return " (in the [[node]] of line " + std::to_string(header + 1) + (id.empty() ? "" : ", id '" + id + "'") + ")";
}

}  // namespace

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
                                        std::to_string(e.source().begin.column) + ": " + std::string(e.description()) +
                                        node_table_around(file, e.source().begin.line));
  }
  Topology topo;
  topo.file = file;
  if (auto ok = only_keys(root, {"deployment", "node"}, file, ""); !ok) return Unexpected<node::Error>{ok.error()};
  TAHVEL_TRY(deployment, table_at(root, "deployment", file, ""));
  topo.name = file.stem().string();
  if (deployment) {
    if (auto ok = only_keys(*deployment, {"name"}, file, "", "deployment."); !ok) return Unexpected<node::Error>{ok.error()};
    TAHVEL_TRY(name, typed<std::string>(*deployment, "name", file, "deployment.", "a string"));
    // Printed by `up` and `status`: a control character there would act on the terminal.
    if (name && std::any_of(name->begin(), name->end(), [](char c) { return static_cast<unsigned char>(c) < 0x20 || c == 0x7f; }))
      return node::fail(Errc::invalid_argument, where(*deployment->get("name"), file) + ": deployment.name: a control character in a name");
    if (name) topo.name = *name;
  }
  if (root.get("node") && !root.get("node")->is_array_of_tables())
    return node::fail(Errc::invalid_argument, where(*root.get("node"), file) + ": node must be [[node]] tables");
  const toml::array* nodes = root["node"].as_array();
  if (!nodes || nodes->empty()) return node::fail(Errc::invalid_argument, file.string() + ": no [[node]] tables");
  std::vector<NodeSpec> specs;
  std::map<std::string, std::size_t> by_id;
  for (const auto& entry : *nodes) {
    const toml::table* t = entry.as_table();
    if (!t) return node::fail(Errc::invalid_argument, where(entry, file) + ": [[node]] must be a table");
    NodeSpec spec;
    TAHVEL_TRY(id, typed<std::string>(*t, "id", file, "node: ", "a string"));
    if (!id) return node::fail(Errc::invalid_argument, where(*t, file) + ": a node needs an id");
    const toml::node& id_at = *t->get("id");  // errors about the id point at it, not at [[node]]
    // The longest name made of an id, supervisor-<id>.apply.lock, must fit a file name (255 bytes).
    // Said before check_id, which would quote the whole id.
    if (id->size() > kMaxNodeIdBytes)
      return node::fail(Errc::invalid_argument, where(id_at, file) + ": node id '" + utf8_prefix(*id, 40) + "...' is " +
                                                    std::to_string(id->size()) + " bytes long; at most " +
                                                    std::to_string(kMaxNodeIdBytes) + " are allowed (the state directory names files after it)");
    // check_id's message shows the id with its control characters escaped: not quoted raw here too.
    if (auto ok = uri::check_id(*id); !ok) return node::fail(Errc::invalid_argument, where(id_at, file) + ": node id: " + ok.error().message);
    spec.id = *id;
    if (by_id.count(spec.id)) return node::fail(Errc::invalid_argument, where(id_at, file) + ": node id '" + spec.id + "' appears twice");
    // STATE/<id> is the node's store, beside the supervisors' files in STATE (the whole file's
    // is supervisor-all.*, one node's supervisor-<id>.*), `up`'s turn (.up.lock) and the stores
    // `up` is making (STATE/<id>.making, which `status` does not take for nodes).
    if (spec.id == "logs" || spec.id == "all" || spec.id.starts_with(".") || spec.id.starts_with("supervisor-") ||
        spec.id.ends_with(".making"))
      return node::fail(Errc::invalid_argument,
                        where(id_at, file) + ": node id '" + spec.id +
                            "' is taken by the state directory's own files (logs/, all, .*, supervisor-*, *.making)");
    const std::string what = "node '" + spec.id + "': ";
    if (auto ok = only_keys(*t, {"id", "iri", "tier", "parent", "up", "listen", "store", "forward", "behaviours", "load", "agent"}, file, what); !ok)
      return Unexpected<node::Error>{ok.error()};
    TAHVEL_TRY(iri, typed<std::string>(*t, "iri", file, what, "a string (an absolute IRI)"));
    TAHVEL_TRY(tier, typed<std::string>(*t, "tier", file, what, "a string"));
    TAHVEL_TRY(parent, typed<std::string>(*t, "parent", file, what, "a string (the parent node's id)"));
    spec.iri = iri.value_or("");
    spec.tier = tier.value_or("");
    spec.parent = parent.value_or("");
    spec.at = where(*t, file);
    spec.parent_at = t->get("parent") ? where(*t->get("parent"), file) : spec.at;
    // An empty parent is a slip, not a root: a root has no `parent` key.
    if (parent && parent->empty())
      return node::fail(Errc::invalid_argument, spec.parent_at + ": " + what +
                                                    "parent is empty: give the parent node's id, or leave the key out for a root");
    spec.iri_at = t->get("iri") ? where(*t->get("iri"), file) : spec.at;
    spec.load_at = t->get("load") ? where(*t->get("load"), file) : spec.at;
    TAHVEL_TRY(up, typed<std::string>(*t, "up", file, what, "\"lcm\" or \"dds\" (which of its parent's listen it links over)"));
    spec.up = up.value_or("");
    spec.up_at = t->get("up") ? where(*t->get("up"), file) : spec.at;
    if (up && *up != "lcm" && *up != "dds")
      return node::fail(Errc::invalid_argument, spec.up_at + ": " + what + "up is " + in_quotes(*up) + ": it must be \"lcm\" or \"dds\"");
    // `listen = { ... }` or, for a node that serves children on both kinds, an array of them.
    if (const toml::node* listen = t->get("listen")) {
      std::vector<const toml::table*> tables;
      if (const toml::array* several = listen->as_array()) {
        for (const auto& one : *several) {
          if (!one.is_table())
            return node::fail(Errc::invalid_argument, where(one, file) + ": " + what + "listen: each entry must be a table { kind = ... }");
          tables.push_back(one.as_table());
        }
        if (tables.empty()) return node::fail(Errc::invalid_argument, where(*listen, file) + ": " + what + "listen is empty");
      } else if (listen->is_table()) {
        tables.push_back(listen->as_table());
      } else {
        return node::fail(Errc::invalid_argument, where(*listen, file) + ": " + what +
                                                      "listen must be a table { kind = ... } or an array of them");
      }
      for (const toml::table* one : tables) {
        auto l = link_spec(*one, file, spec.id);
        if (!l) return Unexpected<node::Error>{l.error()};
        for (const auto& earlier : spec.listen)
          if (earlier.kind == l->kind)
            return node::fail(Errc::invalid_argument, where(*one, file) + ": " + what + "listen: a second kind = \"" + l->kind +
                                                          "\"; a node listens once on each kind");
        spec.listen.push_back(*l);
      }
    }
    TAHVEL_TRY(store, table_at(*t, "store", file, what));
    spec.store_at = t->get("store") ? where(*t->get("store"), file) : spec.at;
    if (store) {
      if (auto ok = only_keys(*store, {"durability", "ring"}, file, what, "store."); !ok) return Unexpected<node::Error>{ok.error()};
      TAHVEL_TRY(durability, typed<std::string>(*store, "durability", file, what + "store.", "\"fast\" or \"durable\""));
      spec.durability = durability.value_or("fast");
      if (spec.durability != "fast" && spec.durability != "durable")
        return node::fail(Errc::invalid_argument, where(*store->get("durability"), file) + ": " + what + "store.durability must be \"fast\" or \"durable\"");
      TAHVEL_TRY(ring, typed<std::int64_t>(*store, "ring", file, what + "store.", "an integer >= 0"));
      if (ring && *ring < 0) return node::fail(Errc::invalid_argument, where(*store->get("ring"), file) + ": " + what + "store.ring must be >= 0");
      spec.ring = static_cast<std::uint64_t>(ring.value_or(0));
    }
    auto forward = strings((*t)["forward"].node(), file, "node '" + spec.id + "': forward");
    if (!forward) return Unexpected<node::Error>{forward.error()};
    spec.forward = *forward;
    spec.forward_given = t->get("forward") != nullptr;
    spec.forward_at = t->get("forward") ? where(*t->get("forward"), file) : spec.at;
    if (const toml::array* patterns = t->get("forward") ? t->get("forward")->as_array() : nullptr)
      for (const auto& e : *patterns) spec.forward_each_at.push_back(where(e, file));
    TAHVEL_TRY(behaviours, typed<std::string>(*t, "behaviours", file, what, "a string (a folder)"));
    if (behaviours) {
      std::filesystem::path p = *behaviours;
      if (p.is_relative()) p = std::filesystem::absolute(file).parent_path() / p;
      spec.behaviours = p.lexically_normal();
      // A misspelt folder would run no behaviour, and say so nowhere.
      if (std::error_code ec; !std::filesystem::is_directory(spec.behaviours, ec))
        return node::fail(Errc::not_found, where(*t->get("behaviours"), file) + ": " + what + "behaviours: " +
                                               spec.behaviours.string() + " is not a folder" +
                                               (std::filesystem::exists(spec.behaviours, ec) ? "" : " (no such directory)"));
    }
    auto load = strings((*t)["load"].node(), file, "node '" + spec.id + "': load");
    if (!load) return Unexpected<node::Error>{load.error()};
    for (const auto& l : *load) {
      std::filesystem::path p = l;
      if (p.is_relative()) p = std::filesystem::absolute(file).parent_path() / p;
      spec.load.push_back(p.lexically_normal());
    }
    if (t->get("agent") && !t->get("agent")->is_array_of_tables())
      return node::fail(Errc::invalid_argument, where(*t->get("agent"), file) + ": " + what + "agent must be [[node.agent]] tables");
    if (const toml::array* agents = (*t)["agent"].as_array()) {
      std::map<std::string, std::uint32_t> seen;  // agent id -> the line of its table
      for (const auto& a : *agents) {
        const toml::table* at = a.as_table();
        if (!at) return node::fail(Errc::invalid_argument, where(a, file) + ": [[node.agent]] must be a table");
        AgentSpec agent;
        TAHVEL_TRY(agent_id, typed<std::string>(*at, "id", file, what + "agent: ", "a string"));
        if (!agent_id) return node::fail(Errc::invalid_argument, where(*at, file) + ": node '" + spec.id + "': an agent needs an id");
        agent.id = *agent_id;
        agent.at = where(*at, file);
        if (auto ok = uri::check_id(agent.id); !ok)
          return node::fail(Errc::invalid_argument, where(*at, file) + ": node '" + spec.id + "': agent id: " + ok.error().message);
        if (auto ok = only_keys(*at, {"id", "run", "run_with_mitdb", "restart"}, file, what + "agent '" + agent.id + "': "); !ok)
          return Unexpected<node::Error>{ok.error()};
        if (auto [earlier, added] = seen.emplace(agent.id, at->source().begin.line); !added)
          return node::fail(Errc::invalid_argument, where(*at, file) + ": node '" + spec.id + "': agent id '" + agent.id +
                                                        "' is taken: the node's agent on line " + std::to_string(earlier->second) + " has it");
        if (const char* owner = agent_id_in_use(agent.id))
          return node::fail(Errc::invalid_argument, where(*at, file) + ": node '" + spec.id + "': agent id '" + agent.id +
                                                        "' is taken: it is " + owner);
        auto run = strings((*at)["run"].node(), file, what + "agent '" + agent.id + "': run");
        if (!run) return Unexpected<node::Error>{run.error()};
        if (run->empty())
          return node::fail(Errc::invalid_argument, where(*at, file) + ": " + what + "agent '" + agent.id + "' needs run = [command, args...]");
        agent.run = *run;
        auto with_mitdb = strings((*at)["run_with_mitdb"].node(), file, what + "agent '" + agent.id + "': run_with_mitdb");
        if (!with_mitdb) return Unexpected<node::Error>{with_mitdb.error()};
        agent.run_with_mitdb = *with_mitdb;
        if (auto r = restart_policy((*at)["restart"].node(), file, what + "agent '" + agent.id + "'"); r) agent.restart = *r;
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
      if (!spec.parent.empty() && !by_id.count(spec.parent)) {
        // No node has an id that is not one: check_id's message shows it escaped.
        if (auto ok = uri::check_id(spec.parent); !ok)
          return node::fail(Errc::invalid_argument, spec.parent_at + ": node '" + spec.id + "': parent: " + ok.error().message);
        std::string nearest;  // a slip of the id ("hom2"), as --node says it
        std::size_t best = 3;
        for (const auto& [id, at] : by_id)
          if (const std::size_t d = uri::edit_distance(spec.parent, id); d < best && id != spec.id) {
            best = d;
            nearest = id;
          }
        return node::fail(Errc::invalid_argument, spec.parent_at + ": node '" + spec.id + "': parent '" + spec.parent +
                                                      "' is not a node of this file" +
                                                      (nearest.empty() ? "" : "; did you mean '" + nearest + "'?"));
      }
      if (!spec.parent.empty() && !placed.count(spec.parent)) continue;
      if (spec.parent.empty()) {
        if (!spec.up.empty())
          return node::fail(Errc::invalid_argument, spec.up_at + ": node '" + spec.id + "': up = \"" + spec.up +
                                                        "\", but it has no parent to link to");
        // Nothing goes up from a root: a forward policy there is a node placed wrong, or a
        // parent forgotten.
        if (spec.forward_given && !spec.forward.empty())
          return node::fail(Errc::invalid_argument, spec.forward_at + ": node '" + spec.id +
                                                        "': forward, but it has no parent to forward to (give it a parent, or leave forward out)");
        if (spec.iri.empty()) return node::fail(Errc::invalid_argument, spec.at + ": node '" + spec.id + "' has no parent, so it is a root, and a root needs an iri (or give it a parent)");
        auto n = uri::node_iri(spec.iri);
        if (!n) return node::fail(Errc::invalid_iri, spec.iri_at + ": node '" + spec.id + "': iri: " + n.error().message);
        spec.iri = *n;
      } else {
        const NodeSpec& parent = specs[by_id[spec.parent]];
        if (const char* owner = agent_id_in_use(spec.id))
          return node::fail(Errc::invalid_argument, spec.at + ": node id '" + spec.id + "' is taken on its parent '" + parent.id +
                                                        "': a child node is agent '" + spec.id + "' of its parent, and that agent is " + owner);
        if (parent.listen.empty())
          return node::fail(Errc::invalid_argument, parent.at + ": node '" + parent.id + "' has children (node '" + spec.id + "') but no listen = { kind = ... }");
        if (spec.up.empty() && parent.listen.size() > 1)
          return node::fail(Errc::invalid_argument, spec.at + ": node '" + spec.id + "': its parent '" + parent.id +
                                                        "' listens on lcm and dds; say which this node links over: up = \"lcm\" or up = \"dds\"");
        if (spec.up.empty()) spec.up = parent.listen.front().kind;
        if (std::none_of(parent.listen.begin(), parent.listen.end(), [&](const LinkSpec& l) { return l.kind == spec.up; }))
          return node::fail(Errc::invalid_argument, spec.up_at + ": node '" + spec.id + "': up = \"" + spec.up + "\", but its parent '" +
                                                        parent.id + "' listens on " + parent.listen.front().kind + " only");
        auto derived = uri::child_node_iri(parent.iri, spec.id);
        if (!derived) return node::fail(Errc::invalid_iri, spec.at + ": node '" + spec.id + "': " + derived.error().message);
        // An id that its IRI writes otherwise (a percent-escape of a letter: "%41" is "A") would
        // be two names: the parent's link knows the child by the id, the child says hello as its IRI.
        if (auto named = uri::child_id(*derived, parent.iri); named && *named != spec.id)
          return node::fail(Errc::invalid_argument, spec.at + ": node id '" + spec.id + "': its IRI <" + *derived + "> writes it '" +
                                                        *named + "'; write id = \"" + *named + "\"");
        if (!spec.iri.empty()) {
          auto given = uri::normalize(spec.iri);
          if (!given || *given != *derived)
            return node::fail(Errc::invalid_argument, spec.iri_at + ": node '" + spec.id + "': iri <" + spec.iri +
                                                          "> must be its parent's IRI + \"/" + spec.id + "\" = <" + *derived + ">");
        }
        spec.iri = *derived;
      }
      topo.nodes.push_back(spec);
      placed.insert(spec.id);
      progress = true;
    }
    if (!progress) {
      // Every node left is on a cycle or below one: follow the parents from one until a node repeats.
      std::vector<std::string> path;
      std::string at;
      for (const auto& spec : specs)
        if (!placed.count(spec.id)) at = spec.id;
      while (std::find(path.begin(), path.end(), at) == path.end()) {
        path.push_back(at);
        at = specs[by_id[at]].parent;
      }
      return node::fail(Errc::invalid_argument, specs[by_id[at]].parent_at + ": node '" + at + "': parent: the parents form a cycle (" +
                                                    describe_cycle(path, at) + ")");
    }
  }
  // Two nodes with one IRI would bind one name twice: their children flip between them.
  std::map<std::string, std::string> by_iri;
  for (const auto& n : topo.nodes) {
    // Its peers would drop every frame it sent, each with a line, and never say why to it.
    if (n.iri.size() > federation::kMaxFrameIriBytes)
      return node::fail(Errc::invalid_argument, n.iri_at + ": node '" + n.id + "': its IRI is " +
                                                    std::to_string(n.iri.size()) + " bytes, over the " +
                                                    std::to_string(federation::kMaxFrameIriBytes) +
                                                    " a link frame's sender may have (docs/protocol.md P4)");
    auto [it, fresh] = by_iri.emplace(n.iri, n.id);
    if (!fresh)
      return node::fail(Errc::invalid_argument, n.iri_at + ": nodes '" + it->second + "' and '" + n.id +
                                                    "' have the same IRI <" + n.iri + ">");
  }
  // A root whose IRI lies below another node's is that node's child or agent by name, yet linked
  // to nothing: its items would pass for that node's subtree wherever they met.
  for (const auto& root : topo.nodes) {
    if (!root.parent.empty()) continue;
    for (const auto& n : topo.nodes)
      if (&n != &root && uri::is_under(root.iri, n.iri))
        return node::fail(Errc::invalid_argument, root.iri_at + ": node '" + root.id + "': iri <" + root.iri + "> lies below node '" +
                                                      n.id + "' <" + n.iri + ">, but it has no parent: give it parent = \"" + n.id +
                                                      "\" (its IRI is then derived), or an IRI of its own");
  }
  for (const auto& n : topo.nodes) {
    for (const NodeSpec* child : topo.children(n.id))
      for (const auto& agent : n.agents)
        if (agent.id == child->id) {
          // The child's line, out of its "FILE:LINE:COL".
          const std::size_t col = child->at.rfind(':'), line = col == 0 || col == std::string::npos ? col : child->at.rfind(':', col - 1);
          const std::string child_line =
              line == std::string::npos ? child->at : "line " + child->at.substr(line + 1, col - line - 1);
          return node::fail(Errc::invalid_argument, agent.at + ": node '" + n.id + "': agent id '" + agent.id +
                                                        "' is also its child node's id (the node of " + child_line +
                                                        "; a child node is agent '" + child->id + "' of its parent)");
        }
  }
  if (auto clear = check_lcm_ports_clear_of_dds(topo); !clear) return Unexpected<node::Error>{clear.error()};
  if (auto one = check_one_dds_configuration_per_domain(topo); !one) return Unexpected<node::Error>{one.error()};
  return topo;
}

namespace {

// The executable `name` found on `path` (a PATH value), or "" when there is none.
std::string find_on_path(const std::string& name, std::string_view path) {
  if (path.empty()) return {};
  while (true) {
    const std::size_t colon = path.find(':');
    const std::string dir(path.substr(0, colon));
    const std::string candidate = (dir.empty() ? std::string(".") : dir) + "/" + name;
    if (access(candidate.c_str(), X_OK) == 0 && !std::filesystem::is_directory(candidate))
      return std::filesystem::absolute(candidate).lexically_normal().string();
    if (colon == std::string_view::npos) return {};
    path.remove_prefix(colon + 1);
  }
}

}  // namespace

node::Result<std::vector<std::string>> expand_agent_command(const AgentSpec& agent, const NodeSpec& node,
                                                            const std::filesystem::path& store,
                                                            const CommandContext& context) {
  const std::string& mitdb = context.mitdb;
  const std::filesystem::path& bin = context.bin;
  const bool use_mitdb = !mitdb.empty() && !agent.run_with_mitdb.empty();
  std::vector<std::string> argv = use_mitdb ? agent.run_with_mitdb : agent.run;
  const std::string what = (agent.at.empty() ? std::string() : agent.at + ": ") + "node '" + node.id + "': agent '" + agent.id + "': ";
  // An empty {mitdb} would make "/100" of "{mitdb}/100": a replay of a file that is not there,
  // failing and restarted for ever, far from its cause.
  const bool wants_mitdb = std::any_of(argv.begin(), argv.end(), [](const std::string& a) { return a.find("{mitdb}") != std::string::npos; });
  if (wants_mitdb && mitdb.empty())
    return node::fail(Errc::invalid_argument, what + "its command uses {mitdb} but TAHVEL_MITDB is not set (set it to a "
                                                     "directory of MIT-BIH records, or put {mitdb} in run_with_mitdb only)");
  if (wants_mitdb && !std::filesystem::is_directory(mitdb))
    return node::fail(Errc::invalid_argument, what + "TAHVEL_MITDB=" + mitdb + " is not a directory");
  const std::pair<std::string, std::string> vars[] = {
      {"{store}", store.string()}, {"{iri}", node.iri}, {"{bin}", bin.string()}, {"{mitdb}", mitdb},
      {"{dir}", context.dir.string()}};
  for (auto& arg : argv) {
    // A misspelt placeholder ("{stor}") would be passed on literally, and the agent would fail
    // and be restarted for ever, far from its cause. (A shell's "${x}" is not one.)
    for (std::size_t open = arg.find('{'); open != std::string::npos; open = arg.find('{', open + 1)) {
      const std::size_t close = arg.find('}', open);
      if (close == std::string::npos) break;
      const std::string name = arg.substr(open, close - open + 1);
      const bool word = name.size() > 2 && std::all_of(name.begin() + 1, name.end() - 1, [](char c) {
        return (c >= 'a' && c <= 'z') || c == '_';
      });
      if (!word || (open > 0 && arg[open - 1] == '$')) continue;
      if (std::none_of(std::begin(vars), std::end(vars), [&](const auto& v) { return v.first == name; }))
        return node::fail(Errc::invalid_argument, what + "unknown placeholder " + name + " in '" + arg +
                                                       "' (known: {store}, {iri}, {bin}, {mitdb}, {dir})");
    }
    for (const auto& [key, value] : vars) {
      for (std::size_t at = arg.find(key); at != std::string::npos; at = arg.find(key, at + value.size()))
        arg.replace(at, key.size(), value);
    }
  }
  // The program itself: a path that is not an executable file, or a bare name not on PATH,
  // would only show as "exited with status 127; restarting" in the supervisor's log.
  std::string& program = argv.front();
  if (program.find('/') != std::string::npos) {
    if (access(program.c_str(), X_OK) != 0 || std::filesystem::is_directory(program)) {
      // Read from where `up` runs, not from the file's directory: said, with the way to the other.
      std::error_code ec;
      const std::string relative =
          program.front() == '/' ? std::string()
                                 : " (a relative path is read from the directory 'up' runs in, " +
                                       std::filesystem::current_path(ec).string() + "; for a program beside the file write {dir}/" +
                                       std::filesystem::path(program).lexically_normal().string() + ")";
      return node::fail(Errc::invalid_argument, what + "cannot run '" + program + "': " +
                                                     (std::filesystem::exists(program) ? "not an executable file" : "no such file") +
                                                     (relative.empty() ? " (programs of this build: {bin}/tahvel-...)" : relative));
    }
  } else if (std::string found = program.empty() ? std::string() : find_on_path(program, context.path); !found.empty()) {
    program = found;  // the supervisor runs what this PATH finds, whatever its own PATH is
  } else {
    return node::fail(Errc::invalid_argument, what + "cannot run '" + program + "': " +
                                                   (program.empty() ? "an empty program name" : "not found on PATH") +
                                                   " (programs of this build: {bin}/tahvel-...)");
  }
  // An ECG replay of a record that is not there, or not readable, would only show as the
  // source failing and restarted for ever in its log: its header and signal files are opened
  // here, as the source opens them.
  if (std::filesystem::path(program).filename() == "tahvel-ecg-source") {
    for (std::size_t i = 1; i < argv.size(); ++i) {
      // `--record PATH` or `--record=PATH`, as the source reads both.
      std::string path;
      if (argv[i] == "--record" && i + 1 < argv.size()) path = argv[i + 1];
      else if (argv[i].starts_with("--record=")) path = argv[i].substr(9);
      else continue;
      if (auto record = aggregation::SignalReader::open(path); !record)
        return node::fail(Errc::invalid_argument, what + "--record " + path + ": " + record.error().message);
    }
  }
  return argv;
}

node::Result<void> check_agent_flags(const AgentSpec& agent, const NodeSpec& node, const std::vector<std::string>& argv,
                                     const CommandContext& context) {
  // The agents of this build stop before they touch anything when TAHVEL_CHECK_ARGS=1
  // (aggregation/agents/agent_runtime.h); another build's, or another program, would run.
  static const std::set<std::string> kChecked = {"tahvel-ecg-source", "tahvel-rpeak", "tahvel-rr", "tahvel-hrv",
                                                 "tahvel-trend", "tahvel-environment", "tahvel-env-motes"};
  const std::filesystem::path program(argv.front());
  std::error_code ec;
  if (!kChecked.count(program.filename().string()) || context.bin.empty() ||
      !std::filesystem::equivalent(program.parent_path(), context.bin, ec))
    return {};
  // With a store that cannot be opened or made: a program of an older build in {bin}, which
  // knows no check, fails to open it (status 1, passed) rather than working on the node's store.
  auto checked_argv = expand_agent_command(agent, node, "/dev/null/tahvel-check-args", context);
  if (!checked_argv) return {};
  // Everything the child needs, made before the fork: `up` may have threads.
  std::vector<char*> args;
  for (std::string& a : *checked_argv) args.push_back(a.data());
  args.push_back(nullptr);
  std::vector<std::string> environment;
  for (char** e = environ; *e != nullptr; ++e)
    if (!std::string_view(*e).starts_with("TAHVEL_CHECK_ARGS=")) environment.emplace_back(*e);
  environment.emplace_back("TAHVEL_CHECK_ARGS=1");
  std::vector<char*> envp;
  for (std::string& e : environment) envp.push_back(e.data());
  envp.push_back(nullptr);
  int err[2];
  if (::pipe2(err, O_CLOEXEC) != 0) return {};  // unchecked rather than refused
  const int null = ::open("/dev/null", O_RDWR | O_CLOEXEC);
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::dup2(err[1], STDERR_FILENO);
    if (null >= 0) ::dup2(null, STDIN_FILENO), ::dup2(null, STDOUT_FILENO);
    ::execve(args[0], args.data(), envp.data());
    ::_exit(127);
  }
  ::close(err[1]);
  if (null >= 0) ::close(null);
  if (pid < 0) {
    ::close(err[0]);
    return {};
  }
  std::string said;
  char buffer[4096];
  // A program that does not stop (it is not of this build after all) is not waited for.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  bool late = false;
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()).count();
    pollfd ready{err[0], POLLIN, 0};
    const int polled = left > 0 ? ::poll(&ready, 1, static_cast<int>(left)) : 0;
    if (polled < 0 && errno == EINTR) continue;
    if (polled == 0) {
      late = true;
      break;
    }
    const ssize_t n = ::read(err[0], buffer, sizeof buffer);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    if (said.size() < 65536) said.append(buffer, static_cast<std::size_t>(n));
  }
  ::close(err[0]);
  if (late) ::kill(pid, SIGKILL);  // pid > 0: the child forked above
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (late || !WIFEXITED(status) || WEXITSTATUS(status) != 2) return {};
  // The program's last line is its reason: "<UTC time> tahvel-hrv: --window: ..." (the usage
  // before it).
  while (!said.empty() && (said.back() == '\n' || said.back() == '\r')) said.pop_back();
  std::string last = said.substr(said.rfind('\n') == std::string::npos ? 0 : said.rfind('\n') + 1);
  if (const std::size_t name = last.find(program.filename().string() + ": "); name != std::string::npos) last = last.substr(name);
  const std::string what = (agent.at.empty() ? std::string() : agent.at + ": ") + "node '" + node.id + "': agent '" + agent.id + "': ";
  return node::fail(Errc::invalid_argument, what + "its command line is refused: " + last);
}

node::Result<void> check_rule_file(const AgentSpec& agent, const NodeSpec& node, const std::vector<std::string>& argv,
                                   const uri::PrefixMap& prefixes) {
  if (argv.size() < 4 || std::filesystem::path(argv[0]).filename() != "tahvel" || argv[1] != "reason") return {};
  const std::string what = (agent.at.empty() ? std::string() : agent.at + ": ") + "node '" + node.id + "': agent '" + agent.id + "': ";
  const std::string& file = argv[3];
  const bool flags_change_parsing = std::any_of(argv.begin() + 4, argv.end(), [](const std::string& a) {
    return a == "--prefix" || a.starts_with("--prefix=") || a == "--default-ns" || a.starts_with("--default-ns=");
  });
  if (flags_change_parsing) {
    if (auto read = reasoner::read_rule_file(file); !read) return node::fail(Errc::invalid_argument, what + read.error().message);
    return {};
  }
  reasoner::ParseOptions parse;
  parse.me = node.iri;
  parse.default_ns = node.iri + "#";
  parse.prefixes = prefixes;
  if (auto rules = reasoner::load_rules(file, parse); !rules) return node::fail(Errc::invalid_argument, what + rules.error().message);
  return {};
}

CommandContext CommandContext::of_this_process() {
  CommandContext context;
  std::error_code ec;
  context.bin = std::filesystem::read_symlink("/proc/self/exe", ec).parent_path();
  const char* mitdb = std::getenv("TAHVEL_MITDB");
  const char* path = std::getenv("PATH");
  context.mitdb = mitdb ? mitdb : "";
  context.path = path ? path : "";
  return context;
}

node::Result<void> check_dds_participants(const Topology& topo, const std::vector<const NodeSpec*>& here) {
  // Per domain: the link processes on it here (one participant each, whichever ends they run),
  // and the listen whose config they take.
  std::map<std::uint32_t, std::pair<std::set<std::string>, const LinkSpec*>> domains;
  std::map<std::uint32_t, std::string> listener;  // domain -> the node whose listen it is
  for (const NodeSpec* spec : here) {
    for (const LinkSpec& l : spec->listen)
      if (l.kind == "dds") {
        auto& [nodes, link] = domains[l.dds_domain];
        nodes.insert(spec->id);
        if (!link) link = &l, listener[l.dds_domain] = spec->id;
      }
    if (const LinkSpec* up = topo.uplink(*spec); up && up->kind == "dds") {
      auto& [nodes, link] = domains[up->dds_domain];
      // Ends of one domain under two files are two endpoints, two participants (the link shares
      // one only when the file is the same: a listen without one takes the uplink's).
      const bool apart = std::any_of(spec->listen.begin(), spec->listen.end(), [&](const LinkSpec& l) {
        return l.kind == "dds" && l.dds_domain == up->dds_domain && !l.dds_config.empty() && l.dds_config != up->dds_config;
      });
      nodes.insert(apart ? spec->id + "/up" : spec->id);
      if (!link) link = up, listener[up->dds_domain] = spec->parent;
    }
  }
  for (const auto& [domain, users] : domains) {
    const auto& [nodes, link] = users;
    if (link->dds_config.empty()) continue;  // Cyclone's defaults or CYCLONEDDS_URI: not read here
    std::ifstream in(link->dds_config, std::ios::binary);
    const std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    // Only "auto" participant indices run out: the default ("none") takes any free port.
    auto element = [&](const std::string& name) -> std::optional<std::string> {
      const std::size_t open = xml.find("<" + name + ">");
      if (open == std::string::npos) return std::nullopt;
      const std::size_t from = open + name.size() + 2, close = xml.find("</" + name + ">", from);
      if (close == std::string::npos) return std::nullopt;
      std::string value = xml.substr(from, close - from);
      value.erase(0, value.find_first_not_of(" \t\r\n"));
      value.erase(value.find_last_not_of(" \t\r\n") + 1);
      return value;
    };
    const auto index = element("ParticipantIndex");
    if (!index || *index != "auto") continue;
    const auto most = element("MaxAutoParticipantIndex");
    // Cyclone's default when the element is absent: 9.
    const unsigned long max_index = most ? std::strtoul(most->c_str(), nullptr, 10) : 9;
    if (nodes.size() <= max_index + 1) continue;
    return node::fail(Errc::invalid_argument,
                      link->url_at + ": node '" + listener[domain] + "': " + std::to_string(nodes.size()) +
                          " DDS participants of links would run on domain " + std::to_string(domain) + " on this machine, but its config " +
                          link->dds_config + " gives participant indices 0.." + std::to_string(max_index) +
                          " (MaxAutoParticipantIndex, ParticipantIndex auto): the links beyond the first " +
                          std::to_string(max_index + 1) + " would fail at every start (\"Failed to find a free participant "
                          "index\"); raise MaxAutoParticipantIndex there, or bring up fewer nodes on this machine (--node)");
  }
  return {};
}

node::Result<void> check_cyclone_uri(const Topology& topo, const std::vector<const NodeSpec*>& here) {
  for (const NodeSpec* spec : here) {
    std::vector<std::pair<const LinkSpec*, std::string>> links;  // the link, and whose listen it is
    for (const LinkSpec& l : spec->listen) links.emplace_back(&l, spec->id);
    if (const LinkSpec* up = topo.uplink(*spec)) links.emplace_back(up, spec->parent);
    for (const auto& [link, owner] : links) {
      if (link->kind != "dds" || !link->dds_config.empty()) continue;
      if (auto unreadable = unreadable_cyclone_uri_file())
        return node::fail(Errc::not_found, link->url_at + ": node '" + owner +
                                               "': listen.kind = \"dds\" without config: Cyclone DDS reads CYCLONEDDS_URI, "
                                               "which names " + *unreadable + ", and that cannot be read (install it, give "
                                               "listen.config, or unset CYCLONEDDS_URI)");
    }
  }
  return {};
}

}  // namespace tahvel::cli
