// The LCM and Cyclone DDS bindings as conformance-suite Bindings (wire_settings.h).
#pragma once

#include <dds/dds.h>
#include <lcm/lcm.h>

#include <map>
#include <mutex>

#include "junk_frame.h"
#include "tahvel/federation/transport.h"
#include "tahvel/federation/wire_names.h"
#include "transport_conformance.h"
#include "wire_settings.h"

namespace tahvel::federation::conformance {

template <class Open>
std::unique_ptr<Transport> opened(Open&& result) {
  EXPECT_TRUE(result) << (result ? "" : result.error().message);
  return result ? std::move(*result) : nullptr;
}

inline Binding lcm_binding() {
  Binding b;
  b.name = "lcm";
  b.open = [](std::string iri, DropLog log) {
    return opened(open_lcm(test_lcm_settings(), iri, std::move(log)));
  };
  // Raw bytes published with plain LCM on the channel the endpoint listens on.
  b.inject_raw = [](const std::string& to, const std::string& bytes) {
    lcm_t* lcm = lcm_create(test_lcm_settings().url.c_str());
    ASSERT_NE(lcm, nullptr);
    EXPECT_EQ(lcm_publish(lcm, lcm_channel(to).c_str(), bytes.data(),
                          static_cast<unsigned>(bytes.size())),
              0);
    lcm_destroy(lcm);
  };
  b.lossless = false;
  return b;
}

// Publishes raw bytes on an endpoint's DDS topic through the network, as a foreign or broken
// peer would: from a second Cyclone domain of this process that appears on the wire as the
// endpoint's domain (Discovery/ExternalDomainId), with a type that claims the name tahvel::Frame
// but is a sequence<octet> (no type information, so the reader matches on the name). The sample
// travels over loopback RTPS and the endpoint's Cyclone receives CDR that is not a Frame.
class DdsGarbageWriter {
 public:
  static DdsGarbageWriter& instance() {
    static DdsGarbageWriter writer;
    return writer;
  }

  void write(const std::string& to, const std::string& bytes) {
    std::lock_guard lock(mutex_);
    ASSERT_GT(participant_, 0) << "garbage writer: " << dds_strretcode(participant_);
    dds_entity_t& writer = writers_[to];
    if (writer == 0) {
      dds_entity_t topic =
          dds_create_topic(participant_, &descriptor_, dds_topic(to).c_str(), nullptr, nullptr);
      ASSERT_GT(topic, 0) << dds_strretcode(topic);
      dds_qos_t* qos = dds_create_qos();
      dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
      dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
      writer = dds_create_writer(participant_, topic, qos, nullptr);
      dds_delete_qos(qos);
      ASSERT_GT(writer, 0) << dds_strretcode(writer);
      ASSERT_TRUE(await_reader(writer)) << "garbage writer matched no reader of " << to;
    }
    tahvel_test_Junk sample{};
    sample.bytes._buffer = reinterpret_cast<uint8_t*>(const_cast<char*>(bytes.data()));
    sample.bytes._length = sample.bytes._maximum = static_cast<uint32_t>(bytes.size());
    sample.bytes._release = false;
    ASSERT_EQ(dds_write(writer, &sample), DDS_RETCODE_OK);
    dds_write_flush(writer);  // the shipped configuration batches writes
  }

 private:
  static constexpr dds_domainid_t kDomain = 230;

  DdsGarbageWriter() {
    DdsSettings settings = test_dds_settings();
    std::string config = settings.config;
    const auto at = config.find("<Discovery>");
    if (at != std::string::npos) {
      config.insert(at + 11,
                    "<ExternalDomainId>" + std::to_string(settings.domain) + "</ExternalDomainId>");
    }
    domain_ = dds_create_domain(kDomain, config.c_str());
    participant_ = domain_ > 0 ? dds_create_participant(kDomain, nullptr, nullptr) : domain_;
  }

  bool await_reader(dds_entity_t writer) {
    dds_set_status_mask(writer, DDS_PUBLICATION_MATCHED_STATUS);
    dds_entity_t ws = dds_create_waitset(participant_);
    dds_waitset_attach(ws, writer, 0);
    bool matched = false;
    for (int i = 0; i < 50 && !matched; ++i) {
      dds_publication_matched_status_t st{};
      dds_get_publication_matched_status(writer, &st);
      matched = st.current_count > 0;
      if (!matched) dds_waitset_wait(ws, nullptr, 0, DDS_MSECS(100));
    }
    dds_delete(ws);
    return matched;
  }

  const dds_topic_descriptor_t descriptor_{tahvel_test_Junk_desc.m_size,
                                           tahvel_test_Junk_desc.m_align,
                                           0,
                                           0,
                                           "tahvel::Frame",
                                           nullptr,
                                           tahvel_test_Junk_desc.m_nops,
                                           tahvel_test_Junk_desc.m_ops,
                                           "",
                                           {nullptr, 0},
                                           {nullptr, 0},
                                           0};
  std::mutex mutex_;
  dds_entity_t domain_ = 0;
  dds_entity_t participant_ = 0;
  std::map<std::string, dds_entity_t> writers_;
};

inline Binding dds_binding() {
  Binding b;
  b.name = "dds";
  b.open = [](std::string iri, DropLog log) {
    return opened(open_dds(test_dds_settings(), iri, std::move(log)));
  };
  b.inject_raw = [](const std::string& to, const std::string& bytes) {
    DdsGarbageWriter::instance().write(to, bytes);
  };
  b.lossless = true;
  b.pushes = true;
  return b;
}

}  // namespace tahvel::federation::conformance
