// What the LCM and DDS bindings promise beyond the conformance suite: wire names, what send()
// refuses, and how opening fails (transport.h, wire_names.h, docs/transports.md).
#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

#include "tahvel/federation/wire_names.h"
#include "wire_settings.h"

namespace tahvel::federation {
namespace {

void require_netns() {
  const char* in = std::getenv("TAHVEL_IN_NETNS");
  ASSERT_TRUE(in != nullptr && std::string(in) == "1")
      << "opens sockets: run under tests/tools/netns-run";
}

TEST(WireNames, AreShortFixedAndDerivedFromTheIri) {
  // FNV-1a of the empty string is the offset basis.
  EXPECT_EQ(lcm_channel(""), "TVcbf29ce484222325");
  EXPECT_EQ(dds_topic(""), "tahvel_frame_cbf29ce484222325");
  const std::string long_iri = "https://example.org/hospital/" + std::string(500, 'x') + "/home1";
  EXPECT_EQ(lcm_channel(long_iri).size(), 18u);
  EXPECT_EQ(lcm_channel(long_iri), lcm_channel(long_iri));
  EXPECT_NE(lcm_channel("http://h/hospital/home1"), lcm_channel("http://h/hospital/home2"));
  EXPECT_EQ(lcm_channel("http://h/a").substr(2), dds_topic("http://h/a").substr(13));
}

class WireSend : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override { require_netns(); }
  std::unique_ptr<Transport> open(const std::string& iri) {
    auto t = GetParam() == "lcm" ? open_lcm(conformance::test_lcm_settings(), iri)
                                 : open_dds(conformance::test_dds_settings(), iri);
    EXPECT_TRUE(t) << (t ? "" : t.error().message);
    return t ? std::move(*t) : nullptr;
  }
};

TEST_P(WireSend, RefusesEmptyToNulInAnIriAndAnOversizedBody) {
  auto a = open("tahvel://wire-send/" + GetParam() + "/a");
  ASSERT_TRUE(a);
  Frame f;
  f.from = a->self();
  f.to = "";
  auto empty = a->send(f);
  ASSERT_FALSE(empty);
  EXPECT_EQ(empty.error().code, Errc::invalid_argument);
  EXPECT_NE(empty.error().message.find("empty `to`"), std::string::npos) << empty.error().message;

  f.to = std::string("tahvel://x\0y", 12);
  auto nul = a->send(f);
  ASSERT_FALSE(nul);
  EXPECT_NE(nul.error().message.find("NUL"), std::string::npos) << nul.error().message;

  f.to = "tahvel://wire-send/" + GetParam() + "/nobody";
  f.body.assign((64u << 20) + 1, 'x');
  auto big = a->send(f);
  ASSERT_FALSE(big);
  EXPECT_EQ(big.error().code, Errc::invalid_argument);
  EXPECT_NE(big.error().message.find("67108865 bytes"), std::string::npos) << big.error().message;
}

INSTANTIATE_TEST_SUITE_P(Wire, WireSend, ::testing::Values("lcm", "dds"),
                         [](const auto& info) { return info.param; });

TEST(WireOpen, EmptyIriIsRefused) {
  require_netns();
  auto lcm = open_lcm(conformance::test_lcm_settings(), "");
  ASSERT_FALSE(lcm);
  EXPECT_EQ(lcm.error().code, Errc::invalid_argument);
  auto dds = open_dds(conformance::test_dds_settings(), "");
  ASSERT_FALSE(dds);
  EXPECT_EQ(dds.error().code, Errc::invalid_argument);
}

TEST(WireOpen, LcmWithAnUnknownProviderFailsNamingTheUrl) {
  require_netns();
  LcmSettings settings;
  settings.url = "nosuchprovider://nowhere";
  auto t = open_lcm(settings, "tahvel://wire-open/lcm");
  ASSERT_FALSE(t);
  EXPECT_EQ(t.error().code, Errc::io);
  EXPECT_NE(t.error().message.find("nosuchprovider://nowhere"), std::string::npos)
      << t.error().message;
}

TEST(WireOpen, DdsRefusesAnotherConfigurationOfADomainThatRuns) {
  require_netns();
  DdsSettings settings = conformance::test_dds_settings();
  auto first = open_dds(settings, "tahvel://wire-open/dds/1");
  ASSERT_TRUE(first) << first.error().message;
  auto same = open_dds(settings, "tahvel://wire-open/dds/2");
  EXPECT_TRUE(same) << same.error().message;
  DdsSettings other = settings;
  other.config += "<!-- another configuration -->";
  auto refused = open_dds(other, "tahvel://wire-open/dds/3");
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, Errc::invalid_argument);
  EXPECT_NE(refused.error().message.find("another configuration"), std::string::npos)
      << refused.error().message;
  // An empty configuration joins the domain as it runs.
  DdsSettings empty = settings;
  empty.config.clear();
  EXPECT_TRUE(open_dds(empty, "tahvel://wire-open/dds/4"));
}

TEST(WireOpen, DdsWithAnInvalidConfigurationFails) {
  require_netns();
  DdsSettings settings;
  settings.domain = 77;
  settings.config =
      "<CycloneDDS><Domain><General><NoSuchSetting>1</NoSuchSetting></General>"
      "</Domain></CycloneDDS>";
  auto t = open_dds(settings, "tahvel://wire-open/dds/bad");
  ASSERT_FALSE(t);
  EXPECT_NE(t.error().message.find("dds_create_domain 77"), std::string::npos) << t.error().message;
  // The failed domain is not left registered: a good configuration of it works afterwards.
  settings.config = conformance::test_dds_settings().config;
  auto good = open_dds(settings, "tahvel://wire-open/dds/good");
  EXPECT_TRUE(good) << (good ? "" : good.error().message);
}

}  // namespace
}  // namespace tahvel::federation
