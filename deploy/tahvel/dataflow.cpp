#include "dataflow.h"

#include <algorithm>
#include <bitset>
#include <filesystem>

namespace tahvel::cli {
namespace {

const std::string kTv = "https://w3id.org/tahvel#";
const std::string kRdfType = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type";
const std::string kSosa = "http://www.w3.org/ns/sosa/";
const std::string kProv = "http://www.w3.org/ns/prov#";

// The kinds of item the chain writes and takes, with their triples as aggregation/whiteboard/
// items.cpp writes them.
enum Kind { recording, chunk, recording_end, rpeaks, rr_series, hrv_window, kKinds };
using Kinds = std::bitset<kKinds>;

// A triple an item of a kind has: its predicate, and its object when that is always the same.
struct Shape {
  std::string p, o;  // o empty: any object
  // False for a triple only some items of the kind carry (the last RR series of a recording its
  // tv:endSample): a forward that takes it passes those items, not the kind (passes).
  bool every = true;
};

const std::vector<Shape>& shapes_of(Kind kind) {
  static const std::vector<Shape> shapes[kKinds] = {
      {{kRdfType, kTv + "EcgRecording"}, {kSosa + "madeBySensor", ""}, {kTv + "samplingRate", ""}, {kTv + "gain", ""},
       {kTv + "baseline", ""}, {kTv + "unit", ""}, {kTv + "sampleFormat", ""}, {kTv + "lead", ""}, {kTv + "leadCalibration", ""}, {kTv + "sensorMaker", ""},
       {kTv + "sensorModel", ""}, {kTv + "filters", ""}, {kTv + "replayedFrom", ""}, {kTv + "sampleDigest", ""},
       {kTv + "startedAt", ""}},
      {{kRdfType, kTv + "EcgChunk"}, {kTv + "recording", ""}, {kTv + "startSample", ""}, {kTv + "frameCount", ""},
       {kTv + "samples", ""}, {kTv + "sampleFormat", "", false}},
      {{kTv + "endSample", ""}},
      {{kRdfType, kTv + "RPeaks"}, {kTv + "recording", ""}, {kTv + "fromSample", ""}, {kTv + "toSample", ""},
       {kTv + "peaks", ""}, {kTv + "emptyGapEnds", "", false}, {kTv + "pWaveGapEnds", "", false},
       {kProv + "wasDerivedFrom", ""}, {kTv + "endSample", "", false}},
      {{kRdfType, kTv + "RrSeries"}, {kTv + "recording", ""}, {kTv + "intervals", ""}, {kProv + "wasDerivedFrom", ""},
       {kTv + "endSample", "", false}},
      {{kRdfType, kSosa + "Observation"}, {kSosa + "observedProperty", kTv + "HeartRateVariability"},
       {kProv + "wasDerivedFrom", ""}, {kProv + "wasAttributedTo", ""}, {kTv + "windowStartS", ""}, {kTv + "windowEndS", ""},
       {kTv + "meanNnMs", ""}, {kTv + "sdnnMs", ""}, {kTv + "rmssdMs", ""}, {kTv + "pnn50Pct", ""}, {kTv + "meanHrBpm", ""},
       {kTv + "lfMs2", ""}, {kTv + "hfMs2", ""}, {kTv + "lfHf", ""}, {kTv + "sd1Ms", ""}, {kTv + "sd2Ms", ""},
       {kTv + "irregularPct", ""}, {kTv + "nnCount", ""}, {kTv + "rrCount", ""}},
  };
  return shapes[kind];
}

// How the file and a warning name what an agent waits for.
const char* what_kind(Kind kind) {
  switch (kind) {
    case recording: return "recordings' descriptions (a tv:EcgRecording)";
    case chunk: return "ECG chunks (tv:samples)";
    case recording_end: return "recordings' ends (tv:endSample)";
    case rpeaks: return "R-peaks (tv:peaks)";
    case rr_series: return "RR intervals (tv:intervals)";
    case hrv_window: return "HRV windows (sosa:observedProperty tv:HeartRateVariability)";
    case kKinds: break;
  }
  return "";
}
const char* writer_of(Kind kind) {
  switch (kind) {
    case recording: case chunk: case recording_end: return "tahvel-ecg-source";
    case rpeaks: return "tahvel-rpeak";
    case rr_series: return "tahvel-rr";
    case hrv_window: return "tahvel-hrv";
    case kKinds: break;
  }
  return "";
}

struct Program {
  Kinds takes, writes;
};

// The shipped programs; nullopt for any other (it may write anything).
std::optional<Program> program_of(const AgentSpec& agent) {
  if (agent.run.empty()) return std::nullopt;
  const std::string name = std::filesystem::path(agent.run.front()).filename().string();
  Program p;
  if (name == "tahvel-ecg-source") {
    p.writes.set(recording).set(chunk).set(recording_end);
  } else if (name == "tahvel-rpeak") {
    p.takes.set(chunk).set(recording);
    p.writes.set(rpeaks);
  } else if (name == "tahvel-rr") {
    p.takes.set(rpeaks).set(recording);
    p.writes.set(rr_series);
  } else if (name == "tahvel-hrv") {
    p.takes.set(rr_series).set(recording);
    p.writes.set(hrv_window);
  } else if (name == "tahvel-trend") {
    p.takes.set(hrv_window);
  } else if (name != "tahvel-env-motes" && name != "tahvel-environment") {
    return std::nullopt;
  }
  return p;
}

// Whether an uplink subscribed to `pattern` may take the items of `kind`: some triple every item
// of the kind has can match it. A subject, or an object the kind does not fix, may match.
bool passes(const node::Pattern& pattern, Kind kind) {
  return std::any_of(shapes_of(kind).begin(), shapes_of(kind).end(), [&](const Shape& shape) {
    if (!shape.every) return false;
    if (pattern.p && (!pattern.p->is_iri() || pattern.p->value != shape.p)) return false;
    if (pattern.o && !shape.o.empty() && (!pattern.o->is_iri() || pattern.o->value != shape.o)) return false;
    return true;
  });
}

// What a node holds: kinds, or anything (a program of the deployment's own, here or below), and
// its agents of the chain that get no input of a kind they take.
struct Holds {
  Kinds kinds;
  bool anything = false;
  std::vector<const AgentSpec*> dry;
  std::vector<std::pair<const NodeSpec*, Kinds>> passed_up;  // by each child (known kinds only)
  // What each such child's forward would pass, had it any: a kind missing here that a child would
  // pass is missing below it, and the warning says so.
  std::vector<std::pair<const NodeSpec*, Kinds>> passable_up;
};

class Flow {
 public:
  Flow(const Topology& topo, const ForwardPolicies& policies) : topo_(topo), policies_(policies) {}

  const Holds& holds(const NodeSpec& spec) {
    if (auto known = memo_.find(spec.id); known != memo_.end()) return known->second;
    Holds h;
    for (const NodeSpec* child : topo_.children(spec.id)) {
      const Holds& below = holds(*child);
      auto policy = policies_.find(child->id);
      if (policy == policies_.end() || !policy->second) {
        h.anything |= below.anything || below.kinds.any();
        continue;
      }
      Kinds passable;
      for (int k = 0; k < kKinds; ++k)
        for (const node::Pattern& pattern : *policy->second)
          if (passes(pattern, static_cast<Kind>(k))) passable.set(k);
      const Kinds passed = below.anything ? passable : passable & below.kinds;
      h.kinds |= passed;
      if (!below.anything) {
        h.passed_up.emplace_back(child, passed);
        h.passable_up.emplace_back(child, passable);
      }
    }
    std::vector<std::pair<const AgentSpec*, Program>> waiting;
    for (const AgentSpec& agent : spec.agents) {
      if (auto program = program_of(agent)) waiting.emplace_back(&agent, *program);
      else h.anything = true;
    }
    // An agent writes once everything it takes is here: in the order of the chain, whatever the
    // order of the file.
    for (bool more = true; more && !h.anything;) {
      more = false;
      for (auto it = waiting.begin(); it != waiting.end();) {
        if ((it->second.takes & ~h.kinds).none()) {
          h.kinds |= it->second.writes;
          it = waiting.erase(it);
          more = true;
        } else {
          ++it;
        }
      }
    }
    if (!h.anything)
      for (const auto& [agent, program] : waiting) h.dry.push_back(agent);
    return memo_.emplace(spec.id, std::move(h)).first->second;
  }

 private:
  const Topology& topo_;
  const ForwardPolicies& policies_;
  std::map<std::string, Holds> memo_;
};

// "a", "a and b", "a, b and c".
std::string list_of(const std::vector<std::string>& names) {
  std::string list;
  for (std::size_t i = 0; i < names.size(); ++i) list += (i == 0 ? "" : i + 1 == names.size() ? " and " : ", ") + names[i];
  return list;
}

std::string program_name(const AgentSpec& agent) { return std::filesystem::path(agent.run.front()).filename().string(); }

// The agent id a shipped program runs as on its node's board: its --agent, else the program's
// default; nullopt for any other program (what it runs as is not known here). `with_mitdb`:
// TAHVEL_MITDB is set, and an agent with run_with_mitdb runs that.
std::optional<std::string> board_agent_id(const AgentSpec& spec, bool with_mitdb) {
  AgentSpec agent = spec;
  if (with_mitdb && !spec.run_with_mitdb.empty()) agent.run = spec.run_with_mitdb;
  if (agent.run.empty()) return std::nullopt;
  static const std::map<std::string, std::string> kDefaults = {
      {"tahvel-ecg-source", "ecg"}, {"tahvel-rpeak", "rpeak"},   {"tahvel-rr", "rr"},
      {"tahvel-hrv", "hrv"},        {"tahvel-trend", "trend"},   {"tahvel-environment", "environment"}};
  std::string fallback;
  std::size_t flags_from = 1;
  if (auto it = kDefaults.find(program_name(agent)); it != kDefaults.end()) {
    fallback = it->second;
  } else if (program_name(agent) == "tahvel" && agent.run.size() > 1 && agent.run[1] == "reason") {
    fallback = "reasoner";
    flags_from = 2;
  } else {
    return std::nullopt;
  }
  for (std::size_t i = flags_from; i < agent.run.size(); ++i) {
    if (agent.run[i] == "--agent" && i + 1 < agent.run.size()) return agent.run[i + 1];
    if (agent.run[i].starts_with("--agent=")) return agent.run[i].substr(8);
  }
  return fallback;
}

}  // namespace

std::optional<std::string> agents_running_as_one(const NodeSpec& spec, bool with_mitdb) {
  std::map<std::string, const AgentSpec*> runs_as;
  for (const AgentSpec& agent : spec.agents) {
    auto id = board_agent_id(agent, with_mitdb);
    if (!id) continue;
    auto [first, fresh] = runs_as.emplace(*id, &agent);
    if (!fresh)
      return agent.at + ": node '" + spec.id + "': agent '" + agent.id + "' (" + program_name(agent) + ") runs as agent <" +
             spec.iri + "/" + *id + ">, as '" + first->second->id + "' (" + first->second->at +
             ") does: one process at a time holds an agent, so it could not run while that one does; give one of them "
             "--agent ID";
  }
  return std::nullopt;
}

std::vector<std::string> dataflow_warnings(const Topology& topo, const ForwardPolicies& policies,
                                           const std::vector<const NodeSpec*>& judged) {
  Flow flow(topo, policies);
  std::vector<std::string> warnings;
  for (const NodeSpec* spec : judged) {
    const Holds& here = flow.holds(*spec);
    // A stage here whose input and output both come up from one child: the child's stage and this
    // one write the same items (named by recording) from one input.
    for (const AgentSpec& agent : spec->agents) {
      auto program = program_of(agent);
      if (!program || program->writes.none() || program->takes.none()) continue;
      const Kinds input = program->takes & ~Kinds().set(recording);
      for (const auto& [child, passed] : here.passed_up) {
        if ((input & ~passed).any() || (program->writes & ~passed).any()) continue;
        std::string writes;
        for (int k = 0; k < kKinds; ++k)
          if (program->writes.test(k)) writes = what_kind(static_cast<Kind>(k));
        warnings.push_back(agent.at + ": node '" + spec->id + "': agent '" + agent.id + "' (" + program_name(agent) + ") writes " +
                           writes + " from what '" + child->id + "' forwards, and '" + child->id +
                           "' forwards its own as well: two writers of one recording's items under the same names "
                           "(forward the input or the results, not both)");
      }
    }
    if (here.anything) continue;
    // What would be here if the dry agents wrote: an input missing even then is a cause. An
    // agent that waits only on dry agents, or on what a cause already lacks, is named after it.
    Kinds would = here.kinds;
    for (const AgentSpec* agent : here.dry) would |= program_of(*agent)->writes;
    Kinds named;
    std::vector<std::pair<const AgentSpec*, Kinds>> causes;
    std::vector<std::string> after;
    for (const AgentSpec* agent : here.dry) {
      const Kinds missing = program_of(*agent)->takes & ~would;
      if ((missing & ~named).any()) {
        causes.emplace_back(agent, missing);
        named |= missing;
      } else {
        after.push_back("'" + agent->id + "'");
      }
    }
    for (std::size_t c = 0; c < causes.size(); ++c) {
      const auto& [agent, missing] = causes[c];
      std::string what, writers;
      for (int k = 0; k < kKinds; ++k) {
        if (!missing.test(k)) continue;
        const Kind kind = static_cast<Kind>(k);
        what += (what.empty() ? "" : " and ") + std::string(what_kind(kind));
        if (writers.find(writer_of(kind)) == std::string::npos) writers += (writers.empty() ? "" : ", ") + std::string(writer_of(kind));
      }
      std::vector<std::string> empty_children;
      bool all_passed = true;  // by each child named
      for (const auto& [child, passable] : here.passable_up)
        if ((passable & missing).any()) {
          empty_children.push_back("'" + child->id + "'");
          all_passed = all_passed && (missing & ~passable).none();
        }
      const std::string children = empty_children.empty() ? "no child of it forwards"
                                   : list_of(empty_children) + ", whose forward passes " + (all_passed ? "them" : "some of them") +
                                         ", " + (empty_children.size() == 1 ? "has" : "have") + " none to forward";
      std::string line = agent->at + ": node '" + spec->id + "': agent '" + agent->id + "' (" + program_name(*agent) + ") takes " +
                         what + ", which no agent of '" + spec->id + "' writes (" + writers + ") and " + children +
                         ": it will write nothing";
      if (c + 1 == causes.size() && !after.empty()) line += ", nor will " + list_of(after);
      warnings.push_back(std::move(line));
    }
  }
  return warnings;
}

}  // namespace tahvel::cli
