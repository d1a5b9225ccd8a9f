// `tahvel` subcommands that change a whiteboard: init, put, load, remove, subscribe.
#include <cctype>
#include <charconv>
#include <filesystem>
#include <iostream>
#include <set>
#include <unordered_map>

#include "commands.h"
#include "vocabulary.h"
#include "tahvel/spatial/area_subscriptions.h"
#include "tahvel/spatial/board.h"
#include "tahvel/spatial/wkt.h"

namespace tahvel::cli {
namespace {

const Flag kFlagContext{"--context", "", "IRI", "addressee or data group of the item (IRI or CURIE)"};
const Flag kFlagPersistent{"--persistent", "", "", "never expire the item by ring or time-to-live"};
const Flag kFlagInputFormat{"--format", "", "nt|ttl",
                            "input syntax; default Turtle, N-Triples for a FILE ending in .nt"};

node::Format input_format(const Args& args, const std::string& path) {
  node::Format guess = path.ends_with(".nt") ? node::Format::ntriples : node::Format::turtle;
  return format_flag(args, guess, /*allow_json=*/false);
}

// FILE (or standard input) as read, and how it was parsed.
struct Input {
  std::string text;
  node::ParseOptions options;
};

// Reads and parses FILE (or standard input): nothing is stored if this fails. `*read` gets the
// text and the options, to name where a triple the store refuses is written (named_where).
std::vector<node::Triple> parse_input(const node::Node& node, const std::string& path,
                                      node::Format format, const uri::PrefixMap& prefixes, Input* read = nullptr) {
  node::ParseOptions options;
  options.format = format;
  options.base_iri = base_iri_of(node);
  options.source_name = path == "-" ? "<stdin>" : path;
  options.prefixes = prefixes;
  std::string text = read_input(path);
  std::vector<node::Triple> triples = check(node::parse_rdf(text, options));
  if (read) *read = {std::move(text), std::move(options)};
  return triples;
}

// A damaged store (or a full disk) fails while a triple is written; the triple is not at fault,
// and naming its line would send the operator to the input.
bool the_input_may_be_at_fault(const node::Error& error) {
  return error.code != node::Errc::corrupt && error.code != node::Errc::io && error.code != node::Errc::version &&
         error.code != node::Errc::store_full;
}

// The store names a triple it refuses by its place in the item ("triple 1501, object: invalid
// IRI ..."): `message` led by where the input writes it ("FILE:LINE:COL: "), as a syntax error
// is, when it names one.
std::string named_where(const Input& input, const node::Error& error) {
  const std::string& message = error.message;
  if (!message.starts_with("triple ") || !the_input_may_be_at_fault(error)) return message;
  const std::uint64_t n = std::strtoull(message.c_str() + 7, nullptr, 10);
  if (n == 0) return message;
  const std::string at = node::locate_triple(input.text, input.options, n - 1);
  return at.empty() ? message : at + ": " + message;
}

// The item fields --context and --persistent set.
node::Item item_frame(const Args& args, const uri::PrefixMap& prefixes) {
  node::Item item;
  if (auto c = args.get("--context")) item.context = parse_iri(*c, prefixes, "--context");
  item.persistent = args.has("--persistent");
  return item;
}

// Prints what a write that committed returned; `done` says it in words for a failed print,
// and `again` what running the command again would do.
void print_number(std::uint64_t n, const std::string& done,
                  const std::string& again = "running the command again would repeat it") {
  std::cout << n << "\n";
  finish_output_after(std::cout, done, again);
}

// Union-find over subjects and blank nodes, for group_by_subject.
class Groups {
 public:
  std::size_t of(const node::Term& term) {
    std::string key = (term.is_blank() ? "_:" : "<") + term.value;
    auto [it, added] = index_.try_emplace(std::move(key), parent_.size());
    if (added) parent_.push_back(parent_.size());
    return it->second;
  }
  std::size_t root(std::size_t x) {
    while (parent_[x] != x) x = parent_[x] = parent_[parent_[x]];
    return x;
  }
  void unite(std::size_t a, std::size_t b) { parent_[root(a)] = root(b); }

 private:
  std::unordered_map<std::string, std::size_t> index_;
  std::vector<std::size_t> parent_;
};

// Stores `items` through store_all, in transactions of about `batch` triples. Returns the
// number of triples stored; on failure names how many were stored by earlier transactions, and
// where `input` writes a triple the store refused: item k's triple j is triple
// `places[k][j]` of the file.
std::uint64_t store_in_batches(node::Agent& agent, std::vector<node::Item> items, std::uint64_t batch,
                               const Input& input, const std::vector<std::vector<std::size_t>>& places,
                               std::vector<std::pair<std::uint64_t, std::size_t>>* written = nullptr) {
  std::uint64_t loaded = 0, pending_triples = 0;
  std::size_t items_before = 0;  // items of the file stored by earlier batches
  std::vector<node::Item> pending;
  auto flush = [&] {
    auto stored = agent.store_all(pending);
    if (!stored) {
      // store_all counts items within the batch ("item 101: ..."): named in the file's terms.
      std::string message = stored.error().message;
      // A batch of one item is refused as that item ("triple 1, object: ..."), without its number.
      if (pending.size() == 1 && message.starts_with("triple ")) message = "item 1: " + message;
      std::size_t end = 0;
      if (message.starts_with("item ")) {
        std::size_t n = 0;
        auto [at, ec] = std::from_chars(message.data() + 5, message.data() + message.size(), n);
        end = ec == std::errc() && at < message.data() + message.size() && *at == ':' && n >= 1 && n <= pending.size()
                  ? static_cast<std::size_t>(at - message.data())
                  : 0;
        if (end) {
          const node::Item& bad = pending[n - 1];
          std::string at;  // "FILE:LINE:COL: " of the triple, when the store named one
          if (std::string_view rest = std::string_view(message).substr(end);
              rest.starts_with(": triple ") && the_input_may_be_at_fault(stored.error())) {
            const std::uint64_t j = std::strtoull(rest.data() + 9, nullptr, 10);
            const std::vector<std::size_t>& place = places.at(items_before + n - 1);
            if (j >= 1 && j <= place.size()) at = node::locate_triple(input.text, input.options, place[j - 1]);
            if (!at.empty()) at += ": ";
          }
          message = at + "item " + std::to_string(items_before + n) + " of the file (subject " +
                    (bad.triples.empty() ? std::string("-") : bad.triples.front().s.to_ntriples()) + ")" + message.substr(end);
        }
      }
      fail(message + " (" + std::to_string(loaded) + " triples were loaded by earlier batches)");
    }
    if (written)
      for (std::size_t i = 0; i < stored->size() && i < pending.size(); ++i) written->emplace_back((*stored)[i], pending[i].triples.size());
    loaded += pending_triples;
    items_before += pending.size();
    pending.clear();
    pending_triples = 0;
  };
  for (node::Item& item : items) {
    pending_triples += item.triples.size();
    pending.push_back(std::move(item));
    if (pending_triples >= batch) flush();
  }
  if (!pending.empty()) flush();
  return loaded;
}

}  // namespace

const Command kInitCommand{
    "init",
    "DIR --iri IRI [--durable] [--ring N] [--max-literal BYTES] [--max-map BYTES]",
    "Create a new whiteboard (node store) in DIR.",
    "DIR is created if missing and must not already hold a store, nor lie inside one. The node's\n"
    "IRI is its name in the network; agents get IRI/ID. Prefixes given with --prefix are stored\n"
    "in the node and known to every later command. Prints nothing on success.",
    {{"--iri", "", "IRI", "the node's IRI (required, absolute), e.g. http://example.org/home1"},
     {"--durable", "", "", "sync every commit to disk (default: fast, no fsync)"},
     {"--ring", "", "N", "keep at most N non-persistent records, dropping the oldest (0: no ring)"},
     {"--max-literal", "", "BYTES", "refuse literals larger than BYTES (default 1048576)"},
     {"--max-map", "", "BYTES", "let the store grow to BYTES, then refuse writes (default 64 GiB; at least 1048576)"}},
    1, 1};

int run_init(const Args& args) {
  node::InitOptions options;
  options.iri = args.required("--iri");
  if (auto iri = uri::node_iri(options.iri); !iri) usage_error("--iri: " + iri.error().message);
  options.durability = args.has("--durable") ? node::Durability::durable : node::Durability::fast;
  options.ring = args.get_u64("--ring", options.ring);
  options.max_literal_bytes = args.get_u64("--max-literal", options.max_literal_bytes);
  options.max_map_bytes = args.get_u64("--max-map", options.max_map_bytes);
  // Checked here, as every other flag's value is, so that it is a usage error naming the flag
  // (Node::init's own refusal names neither the command nor the flag).
  if (options.max_map_bytes < node::kMinMaxMapBytes)
    usage_error("init: --max-map: " + std::to_string(options.max_map_bytes) + " bytes is less than the smallest store, " +
                std::to_string(node::kMinMaxMapBytes) + " bytes (1 MiB)");
  uri::PrefixMap extra = prefixes_with_flags({}, args);  // checked before anything is created
  refuse_inside_a_store("init", args.positional(0), "make the new store in a directory outside it");
  node::Node node = check(node::Node::init(args.positional(0), options));
  for (const auto& [prefix, ns] : extra.entries()) check(node.set_prefix(prefix, ns));
  return kExitOk;
}

const Command kPutCommand{
    "put",
    "DIR [--agent ID] [--context IRI] [--persistent] [--format nt|ttl] [FILE|-]",
    "Store RDF from FILE or standard input as one item; print its id.",
    "The whole input is one item: written atomically, or not at all when any of it is wrong (a\n"
    "syntax error names FILE:LINE:COL). Blank nodes are local to the item. Relative IRIs resolve\n"
    "against the node IRI + \"/\"; the node's prefixes (and --prefix) may be used in Turtle\n"
    "without @prefix lines. A --context below the node addresses the agent its first segment\n"
    "names (NODE/home1/hrv: agent home1, the link of child node home1); when nothing on the node\n"
    "knows that agent, put warns, names the child nodes it knows, and stores the item anyway.",
    {kFlagAgentWriter, kFlagContext, kFlagPersistent, kFlagInputFormat},
    1, 2};

// A floor plan's geometry that will not read is skipped when the plan is read (docs/spatial.md
// S7), and said only there, far from the file that held it: said here too, as a warning (the
// triples are stored as given). So is one read otherwise than its writer may have meant: a
// literal that is not geo:wktLiteral (GML, a language tag) or a CRS that is not applied
// (degrees of EPSG:4326 read as metres).
void warn_of_unreadable_geometry(const std::vector<node::Triple>& triples, const std::string& path) {
  std::size_t warned = 0;
  std::unordered_map<std::string, const node::Term*> floor_of;  // a subject's first tv:floor here
  for (const node::Triple& t : triples) {
    // Two floors for one feature in one input: the one stated last wins (S6), and a plan that
    // reused a room's IRI on two floors lost the first room without a word.
    if (t.p.value == spatial::kTvFloor) {
      auto [first, fresh] = floor_of.emplace(t.s.value, &t.o);
      const auto one = spatial::parse_floor(*first->second), other = spatial::parse_floor(t.o);
      const bool same = *first->second == t.o || (one && other && *one == *other);  // 1 and "1": one floor
      if (!fresh && !same && ++warned <= 20)
        std::cerr << warning_prefix() << (path == "-" ? std::string("<stdin>") : path) << ": <" << t.s.value << "> has two floors, "
                  << first->second->to_ntriples() << " and " << t.o.to_ntriples()
                  << ": a feature has one place (the one stated last is read, docs/spatial.md S6); give each floor's room an IRI of its own\n";
    }
    // A floor that is no whole number takes the feature out of the plan as a malformed one (S5,
    // S7), also said only when the plan is read.
    if (t.p.value == spatial::kTvFloor && !spatial::parse_floor(t.o) && ++warned <= 20) {
      std::cerr << warning_prefix() << (path == "-" ? std::string("<stdin>") : path) << ": <" << t.s.value << "> tv:floor "
                << t.o.to_ntriples() << ": a floor is a whole number within ±1e9 (the feature is skipped when the floor plan is read)\n";
      continue;
    }
    if (t.p.value != spatial::kGeoAsWkt) continue;
    std::string why, read_anyway;
    if (!t.o.is_literal()) why = "a WKT literal is needed, not " + t.o.to_ntriples();
    else if (auto geometry = spatial::parse_wkt(t.o.value); !geometry) why = geometry.error().message;
    else if (!t.o.language.empty() || (t.o.effective_datatype() != spatial::kGeoWktLiteral &&
                                      t.o.effective_datatype() != "http://www.w3.org/2001/XMLSchema#string"))
      read_anyway = "a literal " + (t.o.language.empty() ? "of datatype <" + t.o.datatype + ">" : "tagged @" + t.o.language) +
                    " is read as WKT (geo:wktLiteral expected)";
    else if (const std::string_view crs = spatial::wkt_crs(t.o.value); !crs.empty() && crs != spatial::kCrs84)
      read_anyway = "its CRS <" + std::string(crs) + "> is not applied: a floor plan's coordinates are read as planar, "
                    "in the plan's own frame (docs/spatial.md S1)";
    if ((!why.empty() || !read_anyway.empty()) && ++warned <= 20)
      std::cerr << warning_prefix() << (path == "-" ? std::string("<stdin>") : path) << ": <" << t.s.value
                << "> geo:asWKT: " << (why.empty() ? read_anyway : why + " (the feature is skipped when the floor plan is read)")
                << "\n";
  }
  if (warned > 20) std::cerr << warning_prefix() << warned - 20 << " more geometries warned of\n";
}

// A predicate or class of the tv: vocabulary that it does not define is a misspelling the
// programs reading the board pass over without a word: a floor predicate spelt "flor" left a room on floor 0, and a
// tv: namespace written otherwise (`<http://www.tahvel.org/ns#floor>`) did the same. Said here.
void warn_of_unknown_vocabulary(const std::vector<node::Triple>& triples, const std::string& path) {
  const std::string where = path == "-" ? std::string("<stdin>") : path;
  const std::string rdf_type = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type";
  std::set<std::string> said;
  auto look_at = [&](const node::Term& term) {
    if (!term.is_iri() || said.size() > 20 || said.contains(term.value)) return;
    const std::string& iri = term.value;
    if (iri.starts_with(uri::kTahvelNs)) {
      const std::string_view local = std::string_view(iri).substr(uri::kTahvelNs.size());
      if (is_tahvel_term(local)) return;
      said.insert(iri);
      std::cerr << warning_prefix() << where << ": tv:" << local << " is not a term of the tv: vocabulary (docs/vocabulary.md)";
      if (auto near = nearest_tahvel_term(local)) std::cerr << "; did you mean tv:" << *near << "?";
      std::cerr << " Tahvel's programs pass over it\n";
      return;
    }
    // Another namespace spelt like Tahvel's, with a term of it: <http://www.tahvel.org/ns#floor>.
    const std::size_t hash = iri.find_last_of("#/");
    if (hash == std::string::npos || hash + 1 >= iri.size()) return;
    const std::string_view ns = std::string_view(iri).substr(0, hash + 1), local = std::string_view(iri).substr(hash + 1);
    std::string lower(ns);
    for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (lower.find("tahvel") == std::string::npos || !is_tahvel_term(local)) return;
    said.insert(iri);
    std::cerr << warning_prefix() << where << ": <" << iri << "> is not tv:" << local << ", which is <" << uri::kTahvelNs << local
              << ">: Tahvel's programs pass over it (@prefix tv: <" << uri::kTahvelNs << "> .)\n";
  };
  for (const node::Triple& t : triples) {
    look_at(t.p);
    if (t.p.value == rdf_type) look_at(t.o);
  }
}

// An item addressed (R18) to an agent nothing on this node knows waits in that agent's input
// buffer for ever: `--context H/home9/hrv` at a hospital of home1 and home2 (a typo, or a home
// not yet deployed) was stored without a word. Known: a child node that registered (its state
// is about it), a program supervised as it, anything said about it (a problem), or a
// subscription of it. A warning, not a refusal: the agent may start later.
void warn_of_unknown_addressee(const node::Node& node, const node::Item& item, const node::Agent& writer) {
  if (item.context.empty()) return;
  const std::optional<std::string> agent = node.addressee(item.context);
  // Under this node's IRI, with nothing between its '/' and the next (`<H>//home1/hrv`): no
  // agent's, not the subtree's ("*"), so the item stays here as data, and went nowhere without
  // a word (an exploratory run of session 85).
  const std::string below = node.iri() + (node.iri().ends_with('/') ? "" : "/");
  const auto normal = uri::normalize(item.context);  // as the store compares IRIs: the host's case
  const std::string& context = normal ? *normal : item.context;
  if (!agent && context.starts_with(below) && context.size() > below.size() &&
      (context[below.size()] == '/' || context[below.size()] == '#' || context[below.size()] == '?')) {
    std::cerr << warning_prefix() << "--context <" << item.context << "> lies under this node's IRI <" << node.iri()
              << "> with an empty segment after it, which names no agent and no child node: the item addresses nobody and "
                 "stays here (an agent's or a child's context is <"
              << below << "ID>…)\n";
    return;
  }
  if (!agent || *agent == writer.iri()) return;  // R18: never its own item's addressee
  auto snapshot = node.snapshot();
  if (!snapshot || board_knows_agent(*snapshot, *agent)) return;
  std::string known;
  for (const std::string& child : child_nodes_known(node, *snapshot)) known += (known.empty() ? "" : ", ") + child;
  std::cerr << warning_prefix() << "--context <" << item.context << "> addresses <" << *agent
            << ">, which nothing on this node knows (no child node of that IRI has registered, and no agent of it runs, "
               "subscribes or has said anything): the item waits in its input buffer until one takes it"
            << (known.empty() ? std::string() : "; child nodes known here: " + known) << "\n";
}

// A ring keeps at most N non-persistent records, the oldest going first (R13), and records held
// in input buffers count towards N: an item of more than N, or one written while held records
// fill the ring, that no input buffer holds is reclaimed by its own write. `put` printed its id
// and exited 0 over nothing stored; it says so.
void warn_if_the_ring_took(const node::Node& node, const node::Item& item, std::uint64_t id) {
  if (item.persistent) return;
  auto stats = node.stats();
  if (!stats || stats->ring == 0) return;
  auto snapshot = node.snapshot();
  if (!snapshot) return;
  auto records = snapshot->item(id);
  const bool gone = records ? records->empty() : records.error().code == node::Errc::not_found;
  if (!gone) return;
  // Certain when the item alone is larger than the ring; otherwise another writer's removal
  // may have taken it meanwhile.
  const bool larger = item.triples.size() > stats->ring;
  std::cerr << warning_prefix() << "item " << id << " of " << item.triples.size()
            << " records is gone already: the store's ring keeps at most " << stats->ring
            << " non-persistent records (those waiting in input buffers among them), and "
            << (larger ? "reclaimed it as it was written" : "most likely reclaimed it as it was written")
            << " (put it --persistent, or make the store with a larger --ring)\n";
}

// Records the store's ring (or a TTL) has reclaimed so far (0 without a ring).
std::uint64_t ring_reclaimed(const node::Node& node) {
  auto stats = node.stats();
  return stats && stats->ring != 0 ? stats->reclaimed_records : 0;
}

// The same for `load`, whose batches of many items a small ring takes as they are written: it
// printed the number of triples loaded and exited 0 over an empty store. Only when something was
// reclaimed meanwhile are the loaded items looked for, and those gone counted exactly (another
// writer's records, or items an input buffer holds, may be what the ring took).
void warn_if_the_ring_took_some(const node::Node& node, const std::vector<std::pair<std::uint64_t, std::size_t>>& written,
                                std::uint64_t reclaimed_before) {
  auto stats = node.stats();
  if (!stats || stats->ring == 0 || stats->reclaimed_records <= reclaimed_before) return;
  auto snapshot = node.snapshot();
  if (!snapshot) return;
  std::uint64_t gone_items = 0, gone_triples = 0, triples = 0;
  for (const auto& [id, count] : written) {
    triples += count;
    auto records = snapshot->item(id);
    if (records ? records->empty() : records.error().code == node::Errc::not_found) {
      ++gone_items;
      gone_triples += count;
    }
  }
  if (gone_items == 0) return;
  std::cerr << warning_prefix() << gone_items << " of the " << written.size() << " items loaded (" << gone_triples
            << " of " << triples << " triples) are gone already: the store's ring keeps at most " << stats->ring
            << " non-persistent records (those waiting in input buffers among them) and reclaimed them as the load wrote "
            << "(load with --persistent, or make the store with a larger --ring)\n";
}

int run_put(const Args& args) {
  node::Node node = open_node(args.positional(0));
  uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  std::string path = args.positional().size() > 1 ? args.positional(1) : "-";
  node::Item item = item_frame(args, prefixes);
  refuse_when_output_was_closed();  // after the usage errors (exit 2), before anything is written
  node::Agent agent = check(node.agent(agent_id(args, "cli")));
  Input input;
  item.triples = parse_input(node, path, input_format(args, path), prefixes, &input);
  if (item.triples.empty())
    fail((path == "-" ? std::string("standard input") : path) + ": no triple to put (an item needs at least one)");
  warn_of_unreadable_geometry(item.triples, path);
  warn_of_unknown_vocabulary(item.triples, path);
  warn_of_unknown_addressee(node, item, agent);
  auto stored = [&] {
    SaidIfSlow said("put", args.positional(0));
    return agent.store(item);
  }();
  if (!stored) fail(named_where(input, stored.error()));
  const std::uint64_t id = *stored;
  print_number(id, "item " + std::to_string(id) + " is stored");
  warn_if_the_ring_took(node, item, id);
  return kExitOk;
}

std::vector<std::vector<node::Triple>> group_by_subject(std::vector<node::Triple> triples,
                                                        std::vector<std::vector<std::size_t>>* places) {
  Groups groups;
  std::vector<std::size_t> member(triples.size());
  for (std::size_t i = 0; i < triples.size(); ++i) {
    member[i] = groups.of(triples[i].s);
    if (triples[i].o.is_blank()) groups.unite(member[i], groups.of(triples[i].o));
  }
  std::unordered_map<std::size_t, std::size_t> slot_of_root;
  std::vector<std::vector<node::Triple>> out;
  for (std::size_t i = 0; i < triples.size(); ++i) {
    auto [it, added] = slot_of_root.try_emplace(groups.root(member[i]), out.size());
    if (added) {
      out.emplace_back();
      places->emplace_back();
    }
    out[it->second].push_back(std::move(triples[i]));
    (*places)[it->second].push_back(i);
  }
  return out;
}

const Command kLoadCommand{
    "load",
    "DIR FILE [--agent ID] [--format nt|ttl] [--context IRI] [--persistent] [--batch N]",
    "Bulk-load N-Triples or Turtle; print the number of triples loaded.",
    "The file is parsed whole first (a syntax error stores nothing). Its triples are then split\n"
    "into items, one per subject group: a subject with the blank nodes it points to, merged with\n"
    "any other subject sharing one of those blank nodes (blank nodes are local to an item, so a\n"
    "group is never split). Items are stored through store_all in transactions of about N\n"
    "triples (--batch, default 10000); if a later transaction fails, earlier ones stay stored.\n"
    "A --context addressing an agent nothing on the node knows is warned of, as by put.",
    {kFlagAgentWriter, kFlagInputFormat, kFlagContext, kFlagPersistent,
     {"--batch", "", "N", "triples per transaction (default 10000)"}},
    2, 2};

// `dump` writes subscriptions (R9) with the rest: loaded, one for an agent of this node routes
// items into its input buffer, whether or not that agent ever runs here; one for another node's
// agent routes nothing (write.cpp) but stays, persistent.
void warn_of_subscriptions(const node::Node& node, const std::vector<node::Triple>& triples, const std::string& path) {
  const std::string subscriber = std::string(uri::kTahvelNs) + "subscriber";
  std::set<std::string> here, elsewhere;
  for (const node::Triple& t : triples)
    if (t.p.is_iri() && t.p.value == subscriber && t.o.is_iri())
      // As routing tells them (write.cpp subscriber_of_this_node): the node's IRI as written.
      (t.o.value.starts_with(node.iri()) && uri::child_id(t.o.value, node.iri()) ? here : elsewhere).insert(t.o.value);
  const auto named = [](const std::set<std::string>& agents) {
    std::string out;
    for (const std::string& agent : agents) {
      if (out.size() > 200) return out + ", …";
      out += (out.empty() ? "<" : ", <") + agent + ">";
    }
    return out;
  };
  const std::string file = path == "-" ? std::string("<stdin>") : path;
  const char* ending = "; `tahvel list DIR -p tv:subscriber --format json` names their items, `tahvel remove DIR --item ID` ends one\n";
  if (!here.empty())
    std::cerr << warning_prefix() << file << ": subscriptions of this node's agents " << named(here)
              << " are loaded: their input buffers fill with the matching items stored here, until they take them" << ending;
  if (!elsewhere.empty())
    std::cerr << warning_prefix() << file << ": subscriptions of another node's agents " << named(elsewhere)
              << " are loaded: they route nothing here, and stay as persistent records" << ending;
}

int run_load(const Args& args) {
  node::Node node = open_node(args.positional(0));
  uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  const std::string& path = args.positional(1);
  node::Item frame = item_frame(args, prefixes);
  const std::uint64_t batch = args.get_u64("--batch", 10000);
  if (batch == 0) usage_error("--batch: must be at least 1 (triples per transaction)");
  refuse_when_output_was_closed();  // after the usage errors (exit 2), before anything is written
  node::Agent agent = check(node.agent(agent_id(args, "cli")));
  std::vector<node::Item> items;
  Input input;
  std::vector<node::Triple> triples = parse_input(node, path, input_format(args, path), prefixes, &input);
  warn_of_unreadable_geometry(triples, path);
  warn_of_unknown_vocabulary(triples, path);
  warn_of_unknown_addressee(node, frame, agent);
  warn_of_subscriptions(node, triples, path);
  std::vector<std::vector<std::size_t>> places;
  for (auto& group : group_by_subject(std::move(triples), &places)) {
    items.push_back(frame);
    items.back().triples = std::move(group);
  }
  const std::uint64_t reclaimed_before = ring_reclaimed(node);
  std::vector<std::pair<std::uint64_t, std::size_t>> written;  // item id, its triples
  const std::uint64_t loaded = store_in_batches(agent, std::move(items), batch, input, places, frame.persistent ? nullptr : &written);
  print_number(loaded, std::to_string(loaded) + " triples are loaded");
  if (!frame.persistent) warn_if_the_ring_took_some(node, written, reclaimed_before);
  return kExitOk;
}

const Command kRemoveCommand{
    "remove",
    "DIR (--item ID | [-s S] [-p P] [-o O] [--under IRI] [--since T] [--until T]) [--cascade N] [--local]",
    "Remove an item or the records matching a pattern; print the count.",
    "With --cascade N the sub-trees of the removed records go too (objects that are IRIs or blank\n"
    "nodes, followed N levels). --under IRI alone removes a recording and its chunks (every record\n"
    "whose subject is IRI or below it). --since and --until narrow a pattern to a time range (as\n"
    "in 'tahvel list'): --under <recording>/chunk --until T prunes a recording's raw ECG before\n"
    "T, whole chunks; a range alone is not a pattern (it would take subscriptions and\n"
    "configuration with it).\n"
    "Removed items also leave the input buffers that held them. A pattern leaves subscriptions\n"
    "whole (taking one of their records would change what they match): remove one with --item\n"
    "ID, the id subscribe printed.\n"
    "Copies the node's link sent up (its forwarding policy) or down (configuration) are removed\n"
    "there too, hop by hop, as the link runs; with --local they stay (pruning this node only).",
    {{"--item", "", "ID", "remove every record of item ID (as printed by put)"},
     kFlagS, kFlagP, kFlagO, kFlagUnder, kFlagSince, kFlagUntil, kFlagCascade,
     {"--local", "", "", "remove on this node only: copies sent up or down stay where they are"}},
    1, 1};

// How many records matching `pattern` belong to a subscription's item (one with a
// tv:subscriber record, R9), which a pattern leaves whole.
std::uint64_t subscription_records_matching(const node::Node& node, const node::Pattern& pattern) {
  const node::Snapshot snapshot = check(node.snapshot());
  const std::string subscriber = std::string(uri::kTahvelNs) + "subscriber";
  std::map<std::uint64_t, bool> is_subscription;  // item id -> has a tv:subscriber record
  std::uint64_t kept = 0;
  check(snapshot.for_each(pattern, [&](const node::Record& r) {
    auto [it, fresh] = is_subscription.emplace(r.meta.item, false);
    if (fresh) {
      auto records = snapshot.item(r.meta.item);  // not check(): no throwing through the library's walk
      it->second = records && std::any_of(records->begin(), records->end(), [&](const node::Record& x) {
                     return x.triple.p.is_iri() && x.triple.p.value == subscriber;
                   });
    }
    if (it->second) ++kept;
    return true;
  }));
  return kept;
}

int run_remove(const Args& args) {
  node::Node node = open_node(args.positional(0));
  uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  node::Pattern pattern = pattern_from_args(args, prefixes);
  const unsigned cascade = cascade_flag(args);
  if (args.has("--item") == (pattern_has_triple(pattern) || pattern.under.has_value())) {
    usage_error("remove: give either --item ID or a pattern (-s, -p, -o, --under), which --since and --until may narrow");
  }
  if (args.has("--item") && (pattern.since || pattern.until)) usage_error("remove: --since and --until narrow a pattern, not --item");
  const node::Reach reach = args.has("--local") ? node::Reach::this_node : node::Reach::copies_too;
  refuse_when_output_was_closed();  // after the usage errors (exit 2), before anything is removed
  std::uint64_t removed = 0;
  if (args.has("--item")) {
    removed = check(node.remove_item(args.get_u64("--item", 0), cascade, reach));
  } else {
    removed = check(node.remove(pattern, cascade, reach));
    // Subscriptions are left whole (R9): `remove -p tv:subscriber` printing 0 said nothing why.
    // Only the matches that are a subscription's are counted: another writer's match stored
    // since (an agent writing its conclusion again) was blamed on subscriptions.
    if (const std::uint64_t kept = subscription_records_matching(node, pattern); kept > 0)
      std::cerr << "tahvel: remove: " << kept << " matching record(s) kept: they belong to subscriptions, which a "
                << "pattern leaves whole; remove a subscription with --item ID (the id 'subscribe' printed)\n";
  }
  // An area subscription's declaration removed: its expansions (ordinary subscriptions) would
  // route on until a keeper ran, and none runs without 'tahvel up'. They go now.
  node::Pattern expansions;
  expansions.p = node::Term::iri(spatial::kTvAreaSubscription);
  if (removed > 0 && check(check(node.snapshot()).count(expansions)) > 0) {
    auto synced = spatial::sync_area_subscriptions(node);
    if (!synced) fail("removed, but the area subscriptions could not follow: " + synced.error().message);
    if (synced->added + synced->removed > 0)
      std::cerr << "tahvel: remove: the area subscriptions follow: " << synced->added << " expansion(s) added, " << synced->removed
                << " removed (docs/spatial.md S9)\n";
  }
  print_number(removed, std::to_string(removed) + " records are removed",
               "running it again removes only what matches by then");
  return kExitOk;
}

const Command kSubscribeCommand{
    "subscribe",
    "DIR --agent ID [-s S] [-p P] [-o O] [--earlier] [--area IRI|WKT [--floor N]]",
    "Subscribe an agent to a triple pattern, or to the records of an area; print the subscription id.",
    "From now on every item with at least one triple matching the pattern lands once in the\n"
    "agent's input buffer (see 'tahvel take'). The subscription is itself stored as persistent\n"
    "triples on the whiteboard. With --earlier a new subscription also brings the matching items\n"
    "already on the board into the buffer, oldest first (an agent started after its input).\n"
    "With --area (a room's IRI or CURIE, or a (MULTI)POLYGON in WKT) the agent gets what 'tahvel\n"
    "list --area' selects: matching items whose subject is a feature located in the area or whose\n"
    "source is a sensor there. The printed id is the area subscription's declaration; the node's\n"
    "area keeper ('tahvel up', or 'tahvel areas DIR') keeps it current as sensors are added or\n"
    "moved. 'tahvel remove --item ID' ends it.",
    {{"--agent", "", "ID", "the subscribing agent (required)"}, kFlagS, kFlagP, kFlagO,
     {"--earlier", "", "", "also deliver the matching items already on the board (a new subscription only)"},
     kFlagArea, kFlagFloor},
    1, 1};

int run_subscribe(const Args& args) {
  node::Node node = open_node(args.positional(0));
  uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  args.required("--agent");
  node::Pattern pattern = pattern_from_args(args, prefixes);
  if (!args.has("--area") && args.has("--floor")) usage_error("--floor: only with a WKT --area");
  if (args.has("--area") && args.has("--earlier"))
    usage_error("--earlier: not with --area (an area subscription follows sensors as they move)");
  // The outbox is a stream the parent applies in id order (docs/protocol.md P5, P9): earlier items
  // with ids past what the parent has applied of it would leave the outbox unsent, those after
  // it would go up, and which is which is where the last item that went up happens to be.
  if (args.has("--earlier") && args.get("--agent") == std::optional<std::string>("uplink"))
    usage_error("--earlier: not for the uplink: items stored before a forwarding pattern stay on the node (docs/protocol.md "
                "P5); from above, 'tahvel query --at <this node's IRI>' reads them");
  std::optional<spatial::AreaSpec> given_area;
  if (args.has("--area")) given_area = area_flag(args, prefixes);
  refuse_when_output_was_closed();  // after the usage errors (exit 2), before anything is written
  node::Agent agent = check(node.agent(agent_id(args, "")));
  if (!given_area) {
    const std::uint64_t id = check([&] {
      // With --earlier it delivers what is on the board: slow when that is much.
      std::optional<SaidIfSlow> said;
      if (!args.has("--earlier")) said.emplace("subscribe", args.positional(0));
      return agent.subscribe(pattern, {.earlier = args.has("--earlier")});
    }());
    print_number(id, "subscription " + std::to_string(id) + " is stored");
    return kExitOk;
  }
  const spatial::AreaSpec& area = *given_area;
  {
    // A room that is not on the board is refused, as 'list --area' refuses it: a typo would
    // otherwise wait silently for a room that never comes.
    node::Snapshot snapshot = check(node.snapshot());
    auto board = spatial::load_plan(snapshot);
    if (!board) fail("--area: " + board.error().message);
    if (auto resolved = spatial::resolve_area(*board, area); !resolved)
      fail("--area: " + resolved.error().message);
    for (const std::string& problem : board->problems) std::cerr << "tahvel: subscribe: warning: --area: feature skipped: " << problem << '\n';
  }
  auto declaration = spatial::declare_area_subscription(node, agent, area, pattern);
  if (!declaration) fail("--area: " + declaration.error().message);
  auto synced = spatial::sync_area_subscriptions(node, *declaration);
  if (!synced) fail("--area: " + synced.error().message);
  node::Snapshot snapshot = check(node.snapshot());
  auto expansion = spatial::area_expansion(snapshot, *declaration);
  if (!expansion) fail("--area: " + expansion.error().message);
  const std::size_t sensors = expansion->sensors.size(), features = expansion->features.size();
  std::cerr << "subscribe: " << sensors << (sensors == 1 ? " sensor and " : " sensors and ") << features
            << (features == 1 ? " located feature" : " located features")
            << " in the area now; 'tahvel up' (or 'tahvel areas DIR') keeps it current\n";
  print_number(*declaration, "area subscription " + std::to_string(*declaration) + " is stored");
  return kExitOk;
}

const Command kAreasCommand{
    "areas",
    "DIR [--once]",
    "Keep the node's area subscriptions current (the area keeper that 'tahvel up' runs).",
    "Expands each area subscription ('tahvel subscribe --area') into subscriptions by sensor and\n"
    "by located feature, and again whenever a geometry, a floor or an area subscription is\n"
    "stored or removed. Prints one line per change. Runs until stopped; --once syncs and exits.",
    {{"--once", "", "", "sync once and exit"}},
    1, 1, false};

int run_areas(const Args& args) {
  spatial::AreaSyncReport first;
  auto keeper = spatial::AreaKeeper::open(args.positional(0), &first);
  if (!keeper) fail(args.positional(0) + ": " + keeper.error().message);
  auto print = [](const spatial::AreaSyncReport& r) {
    std::cout << "areas: " << r.declarations << " area subscriptions, " << r.added << " subscriptions added, "
              << r.removed << " removed" << caught_up_text(r) << std::endl;
    for (const std::string& problem : r.problems) std::cerr << "areas: " << problem << std::endl;
  };
  print(first);
  if (args.has("--once")) return kExitOk;
  while (true) {
    auto synced = keeper->poll(std::chrono::milliseconds(1000));
    if (!synced) fail(synced.error().message);
    if (*synced) print(**synced);
  }
}

}  // namespace tahvel::cli
