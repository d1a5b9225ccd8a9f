// The Cyclone DDS binding (docs/transports.md): one participant per endpoint, a reader on the
// topic named after its own IRI (dds_topic()), and one writer per destination IRI, created on
// the first send to it. Tuned for gateway-to-hospital links: many endpoints, each frame wanted
// by exactly one reader.
//
// Why one topic per destination rather than one topic keyed by `to`: matching then happens at
// discovery, so a writer sends a frame only to the addressee's reader. With one shared topic
// every reader in the domain would receive every frame and filter it locally (Cyclone 0.10
// evaluates content filters on the reader side) — a hospital's thousands of homes would each
// receive all downlink traffic. The price is one topic and one writer per destination in the
// sender, and the discovery of each.
//
// Malformed samples never reach the reader: Cyclone rejects them on arrival and logs a warning,
// which dds_domain::watch_rejections routes back here; receive() reports them to the DropLog.
//
// QoS: RELIABLE with KEEP_ALL history on both sides, volatile durability. A reader keeps at most
// kReaderMaxSamples frames not yet taken; when it is full, a writer blocks up to
// kWriteBlocking and then send() fails with Errc::timeout (the frame did not leave).
//
// Packing: the frames of a run (kMoreFollow) to one destination travel as one sample of kind
// kPackedKind, up to kPackBytes of frames, unpacked by the receiver in receive().
//
// Discovery: a writer created by send() first waits (bounded by kMatchWait) until it has matched
// at least one reader, so that a frame sent right after opening reaches a receiver that already
// exists. Only the first send to a destination waits, and never one of a frame that may find
// nobody (Frame::may_find_nobody); if nobody has matched by then the frame goes out to nobody
// (lost; the link resends).
#include <dds/dds.h>
#include <dds/ddsrt/xmlparser.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include "dds_domain.h"
#include "tahvel/federation/transport.h"
#include "tahvel/federation/wire_names.h"
#include "tahvel_frame.h"
#include "wire_common.h"

namespace tahvel::federation {
namespace {

constexpr std::chrono::milliseconds kMatchWait{2000};
constexpr dds_duration_t kWriteBlocking = DDS_SECS(1);
constexpr int32_t kReaderMaxSamples = 4096;
constexpr uint32_t kTakeBatch = 64;

using dds_domain::retcode;

// ---- QoS ----------------------------------------------------------------------------------

struct Qos {
  Qos() : q(dds_create_qos()) {}
  ~Qos() { dds_delete_qos(q); }
  Qos(const Qos&) = delete;
  Qos& operator=(const Qos&) = delete;
  dds_qos_t* q;
};

void reliable_keep_all(dds_qos_t* q, bool reader) {
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, kWriteBlocking);
  dds_qset_history(q, DDS_HISTORY_KEEP_ALL, 0);
  dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
  if (reader) {
    dds_qset_resource_limits(q, kReaderMaxSamples, DDS_LENGTH_UNLIMITED, DDS_LENGTH_UNLIMITED);
  }
}

// ---- The endpoint -------------------------------------------------------------------------

// Packing: the frames of a run (P9b) wait in their writer's pack, and leave as one sample when
// the run ends or the pack is full. Each sample costs Cyclone, at both ends, more than the bytes
// of a small frame: with packs of up to 14,000 bytes (about 24 of the bench's 580-byte item
// frames) the hospital of the bench used 8 µs of CPU per item instead of 9.5, its homes half as
// much, and it took 150,000-175,000 items/s instead of 125,000 (docs/bench.md, session 25). The
// bound keeps a pack, with the sample's IRIs beside it, within Cyclone's default
// MaxMessageSize (14,720 bytes): one datagram, in fragments of FragmentSize.
constexpr std::size_t kPackBytes = 14000;

struct Writer {
  dds_entity_t writer = 0;
  std::once_flag matched_once;  // the first send waits for a matched reader
  std::mutex mu;                // writes in the order of send(); guards the pack
  std::string pack;             // frames of a run that goes on, not yet written (wire::append_packed)
  std::uint64_t packed = 0;     // how many
  std::string pack_from;        // their `from` (one sample has one)
};

class DdsTransport final : public Transport {
 public:
  DdsTransport(const DdsSettings& settings, std::string self, DropLog log)
      : domain_(settings.domain),
        self_(std::move(self)),
        topic_name_(dds_topic(self_)),
        log_(wire::rate_limited(wire::or_stderr(std::move(log)))) {}

  ~DdsTransport() override {
    if (watch_ != 0) dds_domain::unwatch_rejections(watch_);
    if (participant_ > 0) dds_delete(participant_);  // deletes every child entity too
    if (domain_acquired_) dds_domain::release(domain_);
  }

  DdsTransport(const DdsTransport&) = delete;
  DdsTransport& operator=(const DdsTransport&) = delete;

  Result<void> open(const DdsSettings& settings) {
    if (!settings.config.empty()) {
      if (auto ok = check_dds_config(settings.config); !ok) return node::fail(ok.error().code, "open_dds <" + self_ + ">: " + ok.error().message);
    }
    if (auto ok = dds_domain::acquire(settings.domain, settings.config); !ok) {
      return node::fail(ok.error().code, "open_dds <" + self_ + ">: " + ok.error().message);
    }
    domain_acquired_ = true;
    const std::string where = "open_dds <" + self_ + ">: ";
    participant_ = dds_create_participant(domain_, nullptr, nullptr);
    if (participant_ < 0)
      return node::fail(Errc::io, where + "participant: " + retcode(participant_) + dds_domain::cyclone_said());
    dds_entity_t topic =
        dds_create_topic(participant_, &tahvel_Frame_desc, topic_name_.c_str(), nullptr, nullptr);
    if (topic < 0)
      return node::fail(Errc::io, where + "topic " + topic_name_ + ": " + retcode(topic));
    Qos qos;
    reliable_keep_all(qos.q, true);
    reader_ = dds_create_reader(participant_, topic, qos.q, nullptr);
    if (reader_ < 0)
      return node::fail(Errc::io, where + "reader on " + topic_name_ + ": " + retcode(reader_));
    dds_entity_t cond = dds_create_readcondition(reader_, DDS_ANY_STATE);
    waitset_ = dds_create_waitset(participant_);
    if (cond < 0 || waitset_ < 0) {
      return node::fail(
          Errc::io, where + "read condition or waitset: " + retcode(cond < 0 ? cond : waitset_));
    }
    if (dds_return_t rc = dds_waitset_attach(waitset_, cond, 0); rc < 0) {
      return node::fail(Errc::io, where + "waitset attach: " + retcode(rc));
    }
    watch_ = dds_domain::watch_rejections(topic_name_, [this](std::string line) {
      std::lock_guard lock(rejected_mutex_);
      rejected_.push_back("dds <" + self_ + ">: dropped a sample on topic " + topic_name_ +
                          " that is not a tahvel::Frame (Cyclone: " + wire::printable(line, 400) +
                          ")");
    });
    return {};
  }

  const std::string& self() const override { return self_; }

  Result<void> send(const Frame& frame) override {
    if (auto ok = wire::check_sendable(frame, "dds", self_); !ok) return ok;
    auto writer = writer_for(frame.to);
    if (!writer) return node::fail(writer.error().code, writer.error().message);
    Writer& w = **writer;
    if (!frame.may_find_nobody) std::call_once(w.matched_once, [&] { wait_for_reader(w.writer); });
    std::lock_guard lock(w.mu);
    const bool goes_on =
        (frame.kind == FrameKind::up || frame.kind == FrameKind::down) && (frame.ack & kMoreFollow) != 0;
    const std::size_t size = wire::kPackedFrameHeader + frame.body.size();
    // A pack carries one version and fingerprint, this build's: a frame with others goes alone,
    // as it is (as does a pack handed to send()).
    static const std::uint64_t fingerprint = message_fingerprint();
    const bool packable = size <= kPackBytes && frame.version == kProtocolVersion &&
                          frame.fingerprint == fingerprint && static_cast<std::uint8_t>(frame.kind) != kPackedKind;
    if (w.packed > 0 && (!packable || w.pack.size() + size > kPackBytes || w.pack_from != frame.from)) {
      if (auto ok = write_pack(w, frame.to, false); !ok) return ok;
    }
    if (packable && (goes_on || w.packed > 0)) {
      if (w.packed == 0) w.pack_from = frame.from;
      wire::append_packed(w.pack, frame);
      ++w.packed;
      if (goes_on) return {};  // leaves with the run's next frames
      return write_pack(w, frame.to, true);
    }
    return write(w, frame, !goes_on);
  }

  bool on_arrival(std::function<void()> ready) override {
    {
      std::lock_guard lock(ready_mutex_);
      ready_ = ready;
    }
    dds_listener_t* listener = nullptr;
    if (ready) {
      listener = dds_create_listener(this);
      dds_lset_data_available(listener, &DdsTransport::data_available);
    }
    // Cyclone waits here for a listener call under way to return.
    dds_return_t rc = dds_set_listener(reader_, listener);
    if (listener) dds_delete_listener(listener);
    return rc >= 0;
  }

  Result<std::optional<Frame>> receive(std::chrono::milliseconds timeout) override {
    using clock = std::chrono::steady_clock;
    const auto deadline = clock::now() + timeout;
    for (;;) {
      report_rejected();
      if (!queue_.empty()) {
        Frame frame = std::move(queue_.front());
        queue_.pop_front();
        return std::optional<Frame>(std::move(frame));
      }
      if (auto taken = take_some(); !taken)
        return node::fail(taken.error().code, taken.error().message);
      if (!queue_.empty()) continue;
      const auto left =
          std::chrono::duration_cast<std::chrono::nanoseconds>(deadline - clock::now());
      if (left.count() <= 0) return std::optional<Frame>();
      dds_return_t rc = dds_waitset_wait(waitset_, nullptr, 0, left.count());
      if (rc < 0) return node::fail(Errc::io, "dds <" + self_ + ">: waitset wait: " + retcode(rc));
    }
  }

 private:
  Result<Writer*> writer_for(const std::string& to) {
    std::lock_guard lock(writers_mutex_);
    auto it = writers_.find(to);
    if (it != writers_.end()) return it->second.get();
    const std::string name = dds_topic(to);
    // The reader's own topic may be the same one (a frame to self): create_topic then returns
    // the existing entity's equivalent, which is fine.
    dds_entity_t topic =
        dds_create_topic(participant_, &tahvel_Frame_desc, name.c_str(), nullptr, nullptr);
    if (topic < 0) {
      return node::fail(Errc::io, "dds <" + self_ + ">: topic " + name + " for <" +
                                      wire::printable(to) + ">: " + retcode(topic));
    }
    Qos qos;
    reliable_keep_all(qos.q, false);
    auto w = std::make_unique<Writer>();
    w->writer = dds_create_writer(participant_, topic, qos.q, nullptr);
    if (w->writer < 0) {
      return node::fail(Errc::io,
                        "dds <" + self_ + ">: writer on " + name + ": " + retcode(w->writer));
    }
    return writers_.emplace(to, std::move(w)).first->second.get();
  }

  // Writes `frame` as one sample. With Cyclone's Internal/WriteBatch (the configurations we ship
  // set it) a write waits in the writer's packet until a flush: the samples of a run that goes on
  // (P9b) then travel in a few datagrams instead of one each, and the run's end, any other frame
  // or a failure sends what waits. Without it the flush finds nothing to send.
  Result<void> write(Writer& w, const Frame& frame, bool flush) {
    tahvel_Frame msg{};
    msg.version = frame.version;
    msg.fingerprint = frame.fingerprint;
    msg.kind = static_cast<uint8_t>(frame.kind);
    msg.from = const_cast<char*>(frame.from.c_str());
    msg.to = const_cast<char*>(frame.to.c_str());
    msg.seq = frame.seq;
    msg.prev = frame.prev;
    msg.ack = frame.ack;
    msg.body._length = msg.body._maximum = static_cast<uint32_t>(frame.body.size());
    msg.body._buffer = reinterpret_cast<uint8_t*>(const_cast<char*>(frame.body.data()));
    msg.body._release = false;
    if (dds_return_t rc = dds_write(w.writer, &msg); rc < 0) {
      dds_write_flush(w.writer);
      return node::fail(rc == DDS_RETCODE_TIMEOUT ? Errc::timeout : Errc::io,
                        "dds <" + self_ + ">: write on topic " + dds_topic(frame.to) +
                            " failed: " + retcode(rc) + " (" + wire::describe(frame) + ")");
    }
    if (flush) dds_write_flush(w.writer);
    return {};
  }

  // Writes `w`'s pack as one sample of kind kPackedKind (seq = the number of frames in it) and
  // empties it. When the write fails the packed frames are lost with it, as a frame whose send()
  // failed is: this send() fails, and the link sends them again (P8).
  Result<void> write_pack(Writer& w, const std::string& to, bool flush) {
    Frame sample;
    sample.kind = static_cast<FrameKind>(kPackedKind);
    sample.from = w.pack_from;
    sample.to = to;
    sample.seq = w.packed;
    sample.body = std::move(w.pack);
    w.pack.clear();
    w.packed = 0;
    return write(w, sample, flush);
  }

  // Waits until `writer` has matched a reader or kMatchWait has passed, on the writer's
  // publication-matched status (no polling).
  void wait_for_reader(dds_entity_t writer) {
    if (dds_set_status_mask(writer, DDS_PUBLICATION_MATCHED_STATUS) < 0) return;
    dds_entity_t ws = dds_create_waitset(participant_);
    if (ws < 0) return;
    dds_waitset_attach(ws, writer, 0);
    const auto deadline = std::chrono::steady_clock::now() + kMatchWait;
    for (;;) {
      dds_publication_matched_status_t st{};
      if (dds_get_publication_matched_status(writer, &st) < 0 || st.current_count > 0) break;
      const auto left = std::chrono::duration_cast<std::chrono::nanoseconds>(
          deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) break;
      dds_waitset_wait(ws, nullptr, 0, left.count());
    }
    dds_delete(ws);
  }

  // Hands the samples Cyclone rejected (collected on its thread) to the DropLog, on this one.
  void report_rejected() {
    std::vector<std::string> lines;
    {
      std::lock_guard lock(rejected_mutex_);
      lines.swap(rejected_);
    }
    for (const auto& line : lines) log_(line);
  }

  static void data_available(dds_entity_t, void* arg) {
    auto* self = static_cast<DdsTransport*>(arg);
    std::function<void()> ready;
    {
      std::lock_guard lock(self->ready_mutex_);
      ready = self->ready_;
    }
    if (ready) ready();
  }

  // Takes what the reader holds (up to kTakeBatch samples) into queue_, dropping what must not
  // come out of receive().
  Result<void> take_some() {
    void* samples[kTakeBatch] = {};
    dds_sample_info_t infos[kTakeBatch];
    dds_return_t n = dds_take(reader_, samples, infos, kTakeBatch, kTakeBatch);
    if (n < 0)
      return node::fail(Errc::io,
                        "dds <" + self_ + ">: take on " + topic_name_ + ": " + retcode(n));
    for (dds_return_t i = 0; i < n; ++i) {
      // Samples without data report a writer that went away (keyless topic: unregistered).
      if (infos[i].valid_data) accept(*static_cast<const tahvel_Frame*>(samples[i]), infos[i]);
    }
    if (n > 0) dds_return_loan(reader_, samples, n);
    return {};
  }

  void accept(const tahvel_Frame& msg, const dds_sample_info_t& info) {
    Frame frame;
    frame.version = msg.version;
    frame.fingerprint = msg.fingerprint;
    frame.kind = static_cast<FrameKind>(msg.kind);
    frame.from = msg.from != nullptr ? msg.from : "";
    frame.to = msg.to != nullptr ? msg.to : "";
    frame.seq = msg.seq;
    frame.prev = msg.prev;
    frame.ack = msg.ack;
    if (msg.body._length > 0) {
      frame.body.assign(reinterpret_cast<const char*>(msg.body._buffer), msg.body._length);
    }
    auto drop = [&](const Frame& f, const std::string& why) {
      char writer[40];
      std::snprintf(writer, sizeof writer, "%016llx",
                    static_cast<unsigned long long>(info.publication_handle));
      log_("dds <" + self_ + ">: dropped " + wire::describe(f) + " on topic " + topic_name_ +
           " from writer " + writer + ": " + why);
    };
    if (msg.kind == kPackedKind) {
      if (auto why = frame_refusal(frame, self_)) return drop(frame, wire::printable(*why, 600));
      std::string error;
      for (Frame& f : wire::unpack(frame, error)) {
        if (auto why = wire::reject_reason(f, self_)) drop(f, *why);
        else queue_.push_back(std::move(f));
      }
      if (!error.empty()) drop(frame, "a packed sample that does not decode: " + error);
      return;
    }
    if (auto why = wire::reject_reason(frame, self_)) return drop(frame, *why);
    queue_.push_back(std::move(frame));
  }

  dds_domainid_t domain_;
  bool domain_acquired_ = false;
  std::string self_;
  std::string topic_name_;
  DropLog log_;
  dds_entity_t participant_ = 0;
  dds_entity_t reader_ = 0;
  dds_entity_t waitset_ = 0;
  std::mutex writers_mutex_;
  std::map<std::string, std::unique_ptr<Writer>> writers_;
  std::mutex ready_mutex_;
  std::function<void()> ready_;  // on_arrival's
  std::deque<Frame> queue_;  // touched only by the receive() thread
  int watch_ = 0;            // dds_domain::watch_rejections token
  std::mutex rejected_mutex_;
  std::vector<std::string> rejected_;  // drop lines from Cyclone's thread, for receive()
};

}  // namespace

Result<void> check_dds_config(std::string_view xml) {
  const std::size_t first = xml.find_first_not_of(" \t\r\n");
  if (first == std::string_view::npos || xml[first] != '<')
    return node::fail(Errc::invalid_argument, "Cyclone DDS configuration: not XML (it should start with '<', "
                                              "as <CycloneDDS> ... </CycloneDDS> does)");
  struct Outcome {
    std::string message;
    int line = 0;
    bool element = false;
  } outcome;
  ddsrt_xmlp_callbacks callbacks{};
  callbacks.elem_open = [](void* arg, uintptr_t, uintptr_t*, const char*, int) {
    static_cast<Outcome*>(arg)->element = true;
    return 0;
  };
  callbacks.attr = [](void*, uintptr_t, const char*, const char*, int) { return 0; };
  callbacks.elem_data = [](void*, uintptr_t, const char*, int) { return 0; };
  callbacks.elem_close = [](void*, uintptr_t, int) { return 0; };
  callbacks.error = [](void* arg, const char* message, int line) {
    auto* o = static_cast<Outcome*>(arg);
    if (o->message.empty()) {
      o->message = message;
      o->line = line;
    }
  };
  const std::string text(xml);  // the parser reads a NUL-terminated string
  ddsrt_xmlp_state* parser = ddsrt_xmlp_new_string(text.c_str(), &outcome, &callbacks);
  if (parser == nullptr) return node::fail(Errc::io, "Cyclone DDS configuration: cannot start the XML parser");
  // Leniently (a missing or anonymous close tag passes): a configuration refused here must be one
  // Cyclone would refuse too.
  ddsrt_xmlp_set_options(parser, DDSRT_XMLP_ANONYMOUS_CLOSE_TAG | DDSRT_XMLP_MISSING_CLOSE_AS_EOF);
  const int rc = ddsrt_xmlp_parse(parser);
  ddsrt_xmlp_free(parser);
  if (rc < 0 || !outcome.message.empty())
    return node::fail(Errc::invalid_argument, "Cyclone DDS configuration, line " + std::to_string(outcome.line) + ": " +
                                                  (outcome.message.empty() ? "not well-formed XML" : outcome.message));
  if (!outcome.element) return node::fail(Errc::invalid_argument, "Cyclone DDS configuration: no XML element");
  return {};
}

Result<std::unique_ptr<Transport>> open_dds(const DdsSettings& settings, std::string_view self_iri,
                                            DropLog log) {
  if (self_iri.empty() || self_iri.find('\0') != std::string_view::npos) {
    return node::fail(Errc::invalid_argument, "open_dds: the endpoint IRI is empty or has a NUL");
  }
  auto transport = std::make_unique<DdsTransport>(settings, std::string(self_iri), std::move(log));
  if (auto ok = transport->open(settings); !ok)
    return node::fail(ok.error().code, ok.error().message);
  return std::unique_ptr<Transport>(std::move(transport));
}

}  // namespace tahvel::federation
