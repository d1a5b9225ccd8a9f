// Tests of the C API (tahvel.h): roundtrips through a real store in a temporary directory,
// handle checks, error codes and messages, timeouts, and deliver-once with manual ack across
// agent restarts. Each case waits on conditions with deadlines (take's timeout), never sleeps.
#include "tahvel/node/tahvel.h"

#include <gtest/gtest.h>
#include <chrono>
#include <atomic>
#include <pthread.h>
#include <signal.h>
#include <stdlib.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>

#include "tahvel/node/node.h"
#include "temp_dir.h"

namespace {

namespace fs = std::filesystem;

constexpr const char* kNodeIri = "http://example.org/home1";
constexpr const char* kHeartRate = "<https://w3id.org/tahvel#heartRate>";
constexpr int kWaitMs = 5000;  // a deadline for events that should happen at once

// One heart-rate observation as N-Triples.
std::string observation(int n, int bpm) {
  return "<http://example.org/home1/obs/" + std::to_string(n) + "> " + kHeartRate + " \"" +
         std::to_string(bpm) + "\"^^<http://www.w3.org/2001/XMLSchema#integer> .\n";
}

// A string returned by the C API, freed with tahvel_free.
struct Text {
  char* data = nullptr;
  size_t len = 0;
  ~Text() { tahvel_free(data); }
  std::string str() const { return data == nullptr ? std::string() : std::string(data, len); }
};

class CApiTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = (root_ / "store").string();
    ASSERT_EQ(tahvel_node_init(dir_.c_str(), kNodeIri, &node_), TAHVEL_OK) << tahvel_last_error();
  }

  void TearDown() override {
    tahvel_node_close(node_);
  }

  tahvel_agent* open_agent(const char* id) {
    tahvel_agent* agent = nullptr;
    EXPECT_EQ(tahvel_agent_open(node_, id, &agent), TAHVEL_OK) << tahvel_last_error();
    return agent;
  }

  uint64_t store_nt(tahvel_agent* agent, const std::string& text) {
    uint64_t item = 0;
    EXPECT_EQ(tahvel_store(agent, text.data(), text.size(), TAHVEL_FORMAT_NTRIPLES, nullptr, 0,
                           &item),
              TAHVEL_OK)
        << tahvel_last_error();
    return item;
  }

  tahvel::test_support::TempDir tmp_{"tahvel-capi"};
  const fs::path root_ = tmp_.path();
  std::string dir_;
  tahvel_node* node_ = nullptr;
};

TEST_F(CApiTest, IrisFollowTheNodeIri) {
  EXPECT_STREQ(tahvel_node_iri(node_), kNodeIri);
  tahvel_agent* agent = open_agent("example-c");
  EXPECT_STREQ(tahvel_agent_iri(agent), "http://example.org/home1/example-c");
  tahvel_agent_close(agent);
}

TEST_F(CApiTest, StoreTakeAckRoundtrip) {
  tahvel_agent* reader = open_agent("reader");
  tahvel_agent* writer = open_agent("writer");
  uint64_t subscription = 0;
  ASSERT_EQ(tahvel_subscribe(reader, nullptr, kHeartRate, nullptr, &subscription), TAHVEL_OK)
      << tahvel_last_error();
  EXPECT_NE(subscription, 0u);

  const uint64_t stored = store_nt(writer, observation(1, 72));
  ASSERT_NE(stored, 0u);

  uint64_t item = 0;
  Text text;
  ASSERT_EQ(tahvel_take(reader, kWaitMs, &item, &text.data, &text.len), TAHVEL_OK)
      << tahvel_last_error();
  EXPECT_EQ(item, stored);
  EXPECT_EQ(text.str(), observation(1, 72));
  EXPECT_EQ(std::strlen(text.data), text.len);  // NUL-terminated
  EXPECT_EQ(tahvel_ack(reader, item), TAHVEL_OK) << tahvel_last_error();
  EXPECT_EQ(tahvel_ack(reader, item), TAHVEL_OK) << "a second ack is not an error";

  EXPECT_EQ(tahvel_take(reader, 0, &item, nullptr, nullptr), TAHVEL_TIMEOUT);
  tahvel_agent_close(writer);
  tahvel_agent_close(reader);
}

TEST_F(CApiTest, SubscribeEarlierBringsWhatWasStoredBeforeTheAgentStarted) {
  tahvel_agent* writer = open_agent("writer");
  const uint64_t before = store_nt(writer, observation(2, 64));
  tahvel_agent* late = open_agent("late");
  ASSERT_EQ(tahvel_subscribe_earlier(late, nullptr, kHeartRate, nullptr, nullptr), TAHVEL_OK)
      << tahvel_last_error();
  tahvel_agent* plain = open_agent("plain");
  ASSERT_EQ(tahvel_subscribe(plain, nullptr, kHeartRate, nullptr, nullptr), TAHVEL_OK);
  uint64_t item = 0;
  EXPECT_EQ(tahvel_take(late, 0, &item, nullptr, nullptr), TAHVEL_OK) << tahvel_last_error();
  EXPECT_EQ(item, before);
  EXPECT_EQ(tahvel_take(plain, 0, &item, nullptr, nullptr), TAHVEL_TIMEOUT);
  EXPECT_EQ(tahvel_subscribe_earlier(nullptr, nullptr, kHeartRate, nullptr, nullptr), TAHVEL_INVALID_ARGUMENT);
  tahvel_agent_close(plain);
  tahvel_agent_close(late);
  tahvel_agent_close(writer);
}

TEST_F(CApiTest, TurtleUsesTheNodePrefixesAndListCascades) {
  tahvel_agent* writer = open_agent("writer");
  store_nt(writer, observation(7, 120));
  const std::string turtle =
      "_:c tv:heartRateClass \"high\" ; prov:wasDerivedFrom <http://example.org/home1/obs/7> .";
  uint64_t item = 0;
  ASSERT_EQ(tahvel_store(writer, turtle.data(), turtle.size(), TAHVEL_FORMAT_TURTLE, nullptr, 0,
                         &item),
            TAHVEL_OK)
      << tahvel_last_error();

  Text text;
  ASSERT_EQ(tahvel_list(node_, nullptr, "<http://www.w3.org/ns/prov#wasDerivedFrom>", nullptr, 1,
                        0, &text.data, &text.len),
            TAHVEL_OK)
      << tahvel_last_error();
  EXPECT_NE(text.str().find("<http://www.w3.org/ns/prov#wasDerivedFrom> "
                            "<http://example.org/home1/obs/7> ."),
            std::string::npos)
      << text.str();
  EXPECT_NE(text.str().find(observation(7, 120)), std::string::npos)
      << "cascade 1 follows the object into the observation:\n"
      << text.str();

  Text limited;
  ASSERT_EQ(tahvel_list(node_, nullptr, "<http://www.w3.org/ns/prov#wasDerivedFrom>", nullptr, 1,
                        1, &limited.data, &limited.len),
            TAHVEL_OK);
  const std::string first = limited.str();
  EXPECT_EQ(std::count(first.begin(), first.end(), '\n'), 1) << first;
  tahvel_agent_close(writer);
}

TEST_F(CApiTest, SubscriptionsAreTriplesFoundByBlankNodeLabel) {
  tahvel_agent* agent = open_agent("reader");
  ASSERT_EQ(tahvel_subscribe(agent, nullptr, kHeartRate, nullptr, nullptr), TAHVEL_OK)
      << tahvel_last_error();
  const std::string me = std::string("<") + tahvel_agent_iri(agent) + ">";
  Text heads;
  ASSERT_EQ(tahvel_list(node_, nullptr, "<https://w3id.org/tahvel#subscriber>", me.c_str(), 0, 0,
                        &heads.data, &heads.len),
            TAHVEL_OK)
      << tahvel_last_error();
  const std::string head = heads.str();
  ASSERT_EQ(head.rfind("_:", 0), 0u) << head;
  const std::string label = head.substr(0, head.find(' '));
  Text triples;
  ASSERT_EQ(tahvel_list(node_, label.c_str(), nullptr, nullptr, 0, 0, &triples.data, &triples.len),
            TAHVEL_OK)
      << tahvel_last_error();
  EXPECT_NE(triples.str().find(label + " <https://w3id.org/tahvel#predicate> " + kHeartRate + " ."),
            std::string::npos)
      << triples.str();
  EXPECT_EQ(tahvel_subscribe(agent, label.c_str(), nullptr, nullptr, nullptr),
            TAHVEL_INVALID_ARGUMENT)
      << "subscriptions refuse blank nodes";
  tahvel_agent_close(agent);
}

TEST_F(CApiTest, ListMatchesTypedLiteralObjects) {
  tahvel_agent* writer = open_agent("writer");
  store_nt(writer, observation(1, 72));
  store_nt(writer, observation(2, 80));
  Text text;
  ASSERT_EQ(tahvel_list(node_, nullptr, kHeartRate,
                        " \"80\"^^<http://www.w3.org/2001/XMLSchema#integer> ", 0, 0, &text.data,
                        &text.len),
            TAHVEL_OK)
      << tahvel_last_error();
  EXPECT_EQ(text.str(), observation(2, 80));

  Text none;
  ASSERT_EQ(tahvel_list(node_, "<http://example.org/nothing>", nullptr, nullptr, 0, 0, &none.data,
                        &none.len),
            TAHVEL_OK);
  ASSERT_NE(none.data, nullptr);
  EXPECT_EQ(none.len, 0u);
  tahvel_agent_close(writer);
}

TEST_F(CApiTest, ContextAndPersistenceReachTheStore) {
  tahvel_agent* writer = open_agent("writer");
  const std::string text = observation(3, 60);
  uint64_t item = 0;
  ASSERT_EQ(tahvel_store(writer, text.data(), text.size(), TAHVEL_FORMAT_NTRIPLES,
                         "<http://example.org/group/a>", 1, &item),
            TAHVEL_OK)
      << tahvel_last_error();
  auto node = tahvel::node::Node::open(dir_);
  ASSERT_TRUE(node) << node.error().message;
  auto snapshot = node->snapshot();
  ASSERT_TRUE(snapshot);
  auto records = snapshot->item(item);
  ASSERT_TRUE(records) << records.error().message;
  ASSERT_EQ(records->size(), 1u);
  EXPECT_EQ(records->front().meta.context, "http://example.org/group/a");
  EXPECT_TRUE(records->front().meta.persistent);
  EXPECT_EQ(records->front().meta.source, "http://example.org/home1/writer");
  tahvel_agent_close(writer);
}

TEST_F(CApiTest, RemoveItem) {
  tahvel_agent* writer = open_agent("writer");
  const uint64_t item = store_nt(writer, observation(1, 72) + observation(2, 73));
  uint64_t removed = 0;
  ASSERT_EQ(tahvel_remove_item(node_, item, 0, &removed), TAHVEL_OK) << tahvel_last_error();
  EXPECT_EQ(removed, 2u);
  Text text;
  ASSERT_EQ(tahvel_list(node_, nullptr, kHeartRate, nullptr, 0, 0, &text.data, &text.len),
            TAHVEL_OK);
  EXPECT_EQ(text.str(), "");
  EXPECT_EQ(tahvel_remove_item(node_, item, 0, &removed), TAHVEL_NOT_FOUND);
  EXPECT_EQ(removed, 0u);
  tahvel_agent_close(writer);
}

TEST_F(CApiTest, NullHandlesAreInvalidArguments) {
  uint64_t id = 1;
  Text text;
  const char nt[] = "<http://a/s> <http://a/p> <http://a/o> .";
  tahvel_node* node = reinterpret_cast<tahvel_node*>(&id);
  EXPECT_EQ(tahvel_node_open(nullptr, &node), TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(node, nullptr) << "out-parameters are cleared on failure";
  EXPECT_EQ(tahvel_node_open(dir_.c_str(), nullptr), TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(tahvel_node_init(nullptr, kNodeIri, nullptr), TAHVEL_INVALID_ARGUMENT);
  tahvel_agent* agent = reinterpret_cast<tahvel_agent*>(&id);
  EXPECT_EQ(tahvel_agent_open(nullptr, "a", &agent), TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(agent, nullptr);
  EXPECT_NE(std::string(tahvel_last_error()).find("tahvel_agent_open"), std::string::npos);
  EXPECT_EQ(tahvel_store(nullptr, nt, sizeof nt - 1, TAHVEL_FORMAT_NTRIPLES, nullptr, 0, &id),
            TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(id, 0u);
  EXPECT_EQ(tahvel_subscribe(nullptr, nullptr, nullptr, nullptr, &id), TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(tahvel_take(nullptr, 0, &id, &text.data, &text.len), TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(text.data, nullptr);
  EXPECT_EQ(tahvel_ack(nullptr, 1), TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(tahvel_list(nullptr, nullptr, nullptr, nullptr, 0, 0, &text.data, &text.len),
            TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(tahvel_remove_item(nullptr, 1, 0, &id), TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(tahvel_node_iri(nullptr), nullptr);
  EXPECT_EQ(tahvel_agent_iri(nullptr), nullptr);
  tahvel_node_close(nullptr);
  tahvel_agent_close(nullptr);
  tahvel_free(nullptr);
}

// Through an FFI every handle is a bare pointer: one kind passed where the other goes is
// refused, and closing it as the wrong kind leaves it open.
TEST_F(CApiTest, ANodeHandleWhereAnAgentGoesAndTheReverseAreInvalidArguments) {
  tahvel_agent* agent = open_agent("a");
  auto* agent_as_node = reinterpret_cast<tahvel_node*>(agent);
  auto* node_as_agent = reinterpret_cast<tahvel_agent*>(node_);
  tahvel_agent* opened = nullptr;
  EXPECT_EQ(tahvel_agent_open(agent_as_node, "b", &opened), TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(opened, nullptr);
  const char nt[] = "<http://a/s> <http://a/p> <http://a/o> .";
  EXPECT_EQ(tahvel_store(node_as_agent, nt, sizeof nt - 1, TAHVEL_FORMAT_NTRIPLES, nullptr, 0, nullptr),
            TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(tahvel_node_iri(agent_as_node), nullptr);
  EXPECT_EQ(tahvel_agent_iri(node_as_agent), nullptr);
  tahvel_node_close(agent_as_node);
  tahvel_agent_close(node_as_agent);
  EXPECT_STREQ(tahvel_agent_iri(agent), "http://example.org/home1/a") << "still open";
  EXPECT_STREQ(tahvel_node_iri(node_), kNodeIri) << "still open";
  tahvel_agent_close(agent);
}

TEST_F(CApiTest, ClosedHandlesAreInvalidArguments) {
  tahvel_node* other = nullptr;
  ASSERT_EQ(tahvel_node_open(dir_.c_str(), &other), TAHVEL_OK) << tahvel_last_error();
  tahvel_agent* agent = open_agent("a");
  tahvel_node_close(other);
  tahvel_agent_close(agent);
  EXPECT_EQ(tahvel_ack(agent, 1), TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(tahvel_agent_iri(agent), nullptr);
  EXPECT_EQ(tahvel_remove_item(other, 1, 0, nullptr), TAHVEL_INVALID_ARGUMENT);
  tahvel_agent_close(agent);  // a second close is ignored
  tahvel_node_close(other);
}

TEST_F(CApiTest, AgentOutlivesItsNodeHandle) {
  tahvel_node* other = nullptr;
  ASSERT_EQ(tahvel_node_open(dir_.c_str(), &other), TAHVEL_OK) << tahvel_last_error();
  tahvel_agent* agent = nullptr;
  ASSERT_EQ(tahvel_agent_open(other, "late", &agent), TAHVEL_OK);
  tahvel_node_close(other);
  store_nt(agent, observation(1, 70));
  tahvel_agent_close(agent);
}

TEST_F(CApiTest, SyntaxErrorNamesLineAndColumnAndStoresNothing) {
  tahvel_agent* writer = open_agent("writer");
  const std::string text = observation(1, 72) + "<http://a/s> <http://a/p> \"unterminated .\n";
  uint64_t item = 99;
  EXPECT_EQ(tahvel_store(writer, text.data(), text.size(), TAHVEL_FORMAT_NTRIPLES, nullptr, 0,
                         &item),
            TAHVEL_SYNTAX);
  EXPECT_EQ(item, 0u);
  const std::string message = tahvel_last_error();
  EXPECT_NE(message.find("tahvel_store: "), std::string::npos) << message;
  EXPECT_NE(message.find(":2:"), std::string::npos) << "line 2 and a column: " << message;

  Text listed;
  ASSERT_EQ(tahvel_list(node_, nullptr, kHeartRate, nullptr, 0, 0, &listed.data, &listed.len),
            TAHVEL_OK);
  EXPECT_EQ(listed.str(), "") << "a failed store leaves nothing behind";
  tahvel_agent_close(writer);
}

TEST_F(CApiTest, BadTermsAndArguments) {
  tahvel_agent* agent = open_agent("a");
  EXPECT_EQ(tahvel_subscribe(agent, "<http://unterminated", nullptr, nullptr, nullptr),
            TAHVEL_SYNTAX);
  EXPECT_NE(std::string(tahvel_last_error()).find("subject term '<http://unterminated': the IRI has no closing '>'"),
            std::string::npos)
      << tahvel_last_error();
  // A prefixed name, as Turtle input to tahvel_store takes: "expected ':', '<', or '_'" at column 1.
  EXPECT_EQ(tahvel_subscribe(agent, nullptr, "tv:heartRate", nullptr, nullptr), TAHVEL_SYNTAX);
  EXPECT_NE(std::string(tahvel_last_error()).find("prefixed names such as ex:name, and bare IRIs or numbers, are not read here"),
            std::string::npos)
      << tahvel_last_error();
  EXPECT_EQ(tahvel_subscribe(agent, "\"literal\"", nullptr, nullptr, nullptr),
            TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(tahvel_subscribe(agent, nullptr, "_:b1", nullptr, nullptr), TAHVEL_INVALID_ARGUMENT);
  // An IRI the syntax lets through but that is not one: named as the term it is, not as the
  // subscription record it would have become ("triple 2, object").
  EXPECT_EQ(tahvel_subscribe(agent, nullptr, "<http://[::1>", nullptr, nullptr), TAHVEL_INVALID_IRI);
  EXPECT_NE(std::string(tahvel_last_error()).find("predicate term '<http://[::1>'"), std::string::npos)
      << tahvel_last_error();
  // A term of two lines: its own line and column, not the wrapper's.
  EXPECT_EQ(tahvel_subscribe(agent, nullptr, nullptr, "\"x\"\n  ^^", nullptr), TAHVEL_SYNTAX);
  EXPECT_NE(std::string(tahvel_last_error()).find("at line 2, column"), std::string::npos) << tahvel_last_error();
  const char* two = "<http://a/o> . <http://a/s> <http://a/p> <http://a/o2>";
  EXPECT_EQ(tahvel_subscribe(agent, nullptr, nullptr, two, nullptr),
            TAHVEL_INVALID_ARGUMENT)
      << "one term only";
  const char nt[] = "<http://a/s> <http://a/p> <http://a/o> .";
  EXPECT_EQ(tahvel_store(agent, nt, sizeof nt - 1, 42, nullptr, 0, nullptr),
            TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(tahvel_store(agent, "", 0, TAHVEL_FORMAT_NTRIPLES, nullptr, 0, nullptr),
            TAHVEL_INVALID_ARGUMENT)
      << "an empty item";
  EXPECT_EQ(tahvel_store(agent, nt, sizeof nt - 1, TAHVEL_FORMAT_NTRIPLES, "not an iri", 0,
                         nullptr),
            TAHVEL_INVALID_IRI);
  // Why, as the C++ API says it, and a byte that is not UTF-8 escaped: the message named the
  // IRI alone, the byte raw (a developer's probe of session 84).
  EXPECT_EQ(tahvel_store(agent, nt, sizeof nt - 1, TAHVEL_FORMAT_NTRIPLES, "rel", 0, nullptr), TAHVEL_INVALID_IRI);
  EXPECT_NE(std::string(tahvel_last_error()).find("context: invalid IRI 'rel' at position 0: no scheme"), std::string::npos)
      << tahvel_last_error();
  EXPECT_EQ(tahvel_store(agent, nt, sizeof nt - 1, TAHVEL_FORMAT_NTRIPLES, "http://x/\xff", 0, nullptr), TAHVEL_INVALID_IRI);
  EXPECT_NE(std::string(tahvel_last_error()).find("'http://x/\\xFF' at position 9: invalid UTF-8 byte 0xFF"), std::string::npos)
      << tahvel_last_error();
  // "<>" is an empty IRI, not "no context": it was stored as none.
  EXPECT_EQ(tahvel_store(agent, nt, sizeof nt - 1, TAHVEL_FORMAT_NTRIPLES, "<>", 0, nullptr),
            TAHVEL_INVALID_IRI);
  tahvel_node* missing = nullptr;
  EXPECT_EQ(tahvel_node_open((root_ / "missing").c_str(), &missing), TAHVEL_NOT_FOUND);
  tahvel_node* again = nullptr;
  EXPECT_EQ(tahvel_node_init(dir_.c_str(), kNodeIri, &again), TAHVEL_EXISTS);
  EXPECT_EQ(again, nullptr);
  tahvel_agent* bad = nullptr;
  EXPECT_EQ(tahvel_agent_open(node_, "a/b", &bad), TAHVEL_INVALID_IRI);
  tahvel_agent_close(agent);
}

TEST_F(CApiTest, TakeTimesOut) {
  tahvel_agent* agent = open_agent("idle");
  ASSERT_EQ(tahvel_subscribe(agent, nullptr, kHeartRate, nullptr, nullptr), TAHVEL_OK);
  uint64_t item = 5;
  Text text;
  text.len = 7;
  EXPECT_EQ(tahvel_take(agent, 50, &item, &text.data, &text.len), TAHVEL_TIMEOUT);
  EXPECT_EQ(item, 0u);
  EXPECT_EQ(text.data, nullptr);
  EXPECT_EQ(text.len, 0u);
  EXPECT_NE(std::string(tahvel_last_error()).find("tahvel_take"), std::string::npos);
  tahvel_agent_close(agent);
}

TEST_F(CApiTest, TakeWakesOnAStoreFromAnotherThread) {
  tahvel_agent* reader = open_agent("reader");
  ASSERT_EQ(tahvel_subscribe(reader, nullptr, kHeartRate, nullptr, nullptr), TAHVEL_OK);
  tahvel_agent* writer = open_agent("writer");
  std::thread thread([&] { store_nt(writer, observation(9, 99)); });
  uint64_t item = 0;
  EXPECT_EQ(tahvel_take(reader, -1, &item, nullptr, nullptr), TAHVEL_OK) << tahvel_last_error();
  thread.join();
  EXPECT_NE(item, 0u);
  tahvel_agent_close(writer);
  tahvel_agent_close(reader);
}

extern "C" void note_signal(int) {}

// While it lives, SIGUSR2 goes to the thread that made it every 50 ms (for up to 5 s), with a
// handler installed without SA_RESTART, as an agent's stop handler is.
class SignalsToThisThread {
 public:
  SignalsToThisThread() {
    struct sigaction action {};
    action.sa_handler = note_signal;
    sigemptyset(&action.sa_mask);
    installed_ = sigaction(SIGUSR2, &action, &before_) == 0;
    signaller_ = std::thread([this, waiting = pthread_self()] {
      for (int i = 0; i < 100 && !done_; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        pthread_kill(waiting, SIGUSR2);
      }
    });
  }
  ~SignalsToThisThread() {
    done_ = true;
    signaller_.join();
    sigaction(SIGUSR2, &before_, nullptr);
  }
  bool installed() const { return installed_; }

 private:
  struct sigaction before_ {};
  bool installed_ = false;
  std::atomic<bool> done_{false};
  std::thread signaller_;
};

// A wait without limit ends when a signal handler (installed without SA_RESTART) runs, as a
// timeout that says so: an agent's SIGTERM handler sets a stop flag, and the agent sees it.
TEST_F(CApiTest, AWaitWithoutLimitEndsWhenASignalHandlerRuns) {
  tahvel_agent* reader = open_agent("reader");
  ASSERT_EQ(tahvel_subscribe(reader, nullptr, kHeartRate, nullptr, nullptr), TAHVEL_OK);
  uint64_t item = 0;
  tahvel_status status = TAHVEL_OK;
  {
    SignalsToThisThread signals;
    ASSERT_TRUE(signals.installed());
    status = tahvel_take(reader, -1, &item, nullptr, nullptr);
  }
  EXPECT_EQ(status, TAHVEL_TIMEOUT);
  EXPECT_NE(std::string(tahvel_last_error()).find("ended by a signal"), std::string::npos) << tahvel_last_error();
  tahvel_agent_close(reader);
}

// So does a watch without limit on a quiet board: it returned only when a write came (after the
// signal it went back to sleep), and a watcher with a stop flag could not stop.
TEST_F(CApiTest, AWatchWithoutLimitEndsWhenASignalHandlerRuns) {
  char* json = nullptr;
  size_t len = 0;
  uint64_t bookmark = 0;
  tahvel_status status = TAHVEL_TIMEOUT;
  {
    SignalsToThisThread signals;
    ASSERT_TRUE(signals.installed());
    status = tahvel_watch(node_, 0, -1, 0, &json, &len, &bookmark);
  }
  EXPECT_EQ(status, TAHVEL_OK) << tahvel_last_error();
  EXPECT_EQ(len, 0u);
  EXPECT_EQ(bookmark, 0u);
  tahvel_free(json);
}

TEST_F(CApiTest, UnackedItemIsDeliveredAgainAfterRestartAckedIsNot) {
  tahvel_agent* reader = open_agent("reader");
  ASSERT_EQ(tahvel_subscribe(reader, nullptr, kHeartRate, nullptr, nullptr), TAHVEL_OK);
  tahvel_agent* writer = open_agent("writer");
  const uint64_t stored = store_nt(writer, observation(1, 72));

  uint64_t item = 0;
  ASSERT_EQ(tahvel_take(reader, kWaitMs, &item, nullptr, nullptr), TAHVEL_OK);
  EXPECT_EQ(item, stored);
  tahvel_agent_close(reader);  // "crash" before the ack

  reader = open_agent("reader");  // restart
  Text text;
  ASSERT_EQ(tahvel_take(reader, kWaitMs, &item, &text.data, &text.len), TAHVEL_OK)
      << "an un-acked item is delivered again: " << tahvel_last_error();
  EXPECT_EQ(item, stored);
  EXPECT_EQ(text.str(), observation(1, 72));
  ASSERT_EQ(tahvel_ack(reader, item), TAHVEL_OK);
  tahvel_agent_close(reader);

  reader = open_agent("reader");  // restart after the ack
  EXPECT_EQ(tahvel_take(reader, 100, &item, nullptr, nullptr), TAHVEL_TIMEOUT)
      << "an acked item is not delivered again";
  tahvel_agent_close(reader);
  tahvel_agent_close(writer);
}

TEST(CApiStatus, StrerrorCoversEveryStatus) {
  for (int s : {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 100, 101}) {
    const char* text = tahvel_strerror(static_cast<tahvel_status>(s));
    ASSERT_NE(text, nullptr);
    EXPECT_STRNE(text, "unknown status") << s;
  }
  EXPECT_STREQ(tahvel_strerror(static_cast<tahvel_status>(12345)), "unknown status");
}

TEST(CApiStatus, LastErrorIsPerThread) {
  EXPECT_EQ(tahvel_ack(nullptr, 1), TAHVEL_INVALID_ARGUMENT);
  const std::string mine = tahvel_last_error();
  std::thread([] {
    EXPECT_STREQ(tahvel_last_error(), "");
    EXPECT_EQ(tahvel_take(nullptr, 0, nullptr, nullptr, nullptr), TAHVEL_INVALID_ARGUMENT);
  }).join();
  EXPECT_EQ(mine, tahvel_last_error());
}

}  // namespace

namespace {

TEST_F(CApiTest, TakeAsJsonCarriesWhoWroteItAndWhen) {
  tahvel_agent* reader = open_agent("reader");
  tahvel_agent* writer = open_agent("ecg");
  ASSERT_EQ(tahvel_subscribe(reader, nullptr, kHeartRate, nullptr, nullptr), TAHVEL_OK);
  uint64_t sent = store_nt(writer, observation(1, 72));
  uint64_t pending = 0;
  ASSERT_EQ(tahvel_pending(reader, &pending), TAHVEL_OK);
  EXPECT_EQ(pending, 1u);
  uint64_t item = 0;
  Text text;
  ASSERT_EQ(tahvel_take_as(reader, kWaitMs, TAHVEL_FORMAT_JSON, &item, &text.data, &text.len), TAHVEL_OK)
      << tahvel_last_error();
  EXPECT_EQ(item, sent);
  EXPECT_NE(text.str().find("\"source\":\"http://example.org/home1/ecg\""), std::string::npos) << text.str();
  EXPECT_NE(text.str().find("\"stored_at\":"), std::string::npos);
  Text bad;
  EXPECT_EQ(tahvel_take_as(reader, 0, TAHVEL_FORMAT_TURTLE, &item, &bad.data, &bad.len), TAHVEL_INVALID_ARGUMENT);
  // Its errors name the function called (they named tahvel_take).
  EXPECT_EQ(std::string(tahvel_last_error()).rfind("tahvel_take_as: format ", 0), 0u) << tahvel_last_error();
  ASSERT_EQ(tahvel_ack(reader, sent), TAHVEL_OK) << tahvel_last_error();
  EXPECT_EQ(tahvel_take_as(reader, 0, TAHVEL_FORMAT_JSON, &item, &bad.data, &bad.len), TAHVEL_TIMEOUT);
  EXPECT_EQ(std::string(tahvel_last_error()), "tahvel_take_as: no item within 0 ms");
  EXPECT_EQ(tahvel_take(reader, 0, &item, &bad.data, &bad.len), TAHVEL_TIMEOUT);
  EXPECT_EQ(std::string(tahvel_last_error()), "tahvel_take: no item within 0 ms");
  tahvel_agent_close(writer);
  tahvel_agent_close(reader);
}

TEST_F(CApiTest, UnsubscribeStopsDeliveryAndUnknownIdIsNotFound) {
  tahvel_agent* reader = open_agent("reader");
  tahvel_agent* writer = open_agent("ecg");
  uint64_t sub = 0;
  ASSERT_EQ(tahvel_subscribe(reader, nullptr, kHeartRate, nullptr, &sub), TAHVEL_OK);
  uint64_t again = 0;
  ASSERT_EQ(tahvel_subscribe(reader, nullptr, kHeartRate, nullptr, &again), TAHVEL_OK);
  EXPECT_EQ(again, sub);  // idempotent
  ASSERT_EQ(tahvel_unsubscribe(reader, sub), TAHVEL_OK);
  store_nt(writer, observation(1, 72));
  uint64_t pending = 1;
  ASSERT_EQ(tahvel_pending(reader, &pending), TAHVEL_OK);
  EXPECT_EQ(pending, 0u);
  EXPECT_EQ(tahvel_unsubscribe(reader, sub), TAHVEL_NOT_FOUND);
  tahvel_agent_close(writer);
  tahvel_agent_close(reader);
}

TEST_F(CApiTest, WatchResumesFromItsBookmarkAndReportsRemovals) {
  tahvel_agent* writer = open_agent("ecg");
  uint64_t first = store_nt(writer, observation(1, 72));
  Text batch;
  uint64_t bookmark = 0;
  ASSERT_EQ(tahvel_watch(node_, 0, kWaitMs, 0, &batch.data, &batch.len, &bookmark), TAHVEL_OK)
      << tahvel_last_error();
  EXPECT_NE(batch.str().find("\"id\":" + std::to_string(first)), std::string::npos) << batch.str();
  EXPECT_GE(bookmark, first);
  ASSERT_EQ(tahvel_remove_item(node_, first, 0, nullptr), TAHVEL_OK);
  Text removal;
  uint64_t after = 0;
  ASSERT_EQ(tahvel_watch(node_, bookmark, kWaitMs, 0, &removal.data, &removal.len, &after), TAHVEL_OK);
  EXPECT_NE(removal.str().find("\"removed\":true"), std::string::npos) << removal.str();
  EXPECT_GT(after, bookmark);
  Text none;
  uint64_t same = 0;
  ASSERT_EQ(tahvel_watch(node_, after, 10, 0, &none.data, &none.len, &same), TAHVEL_OK);
  EXPECT_EQ(none.str(), "");
  EXPECT_EQ(same, after);
  // Without json_out the changes have nowhere to go: refused, the bookmark where it was (it
  // moved past changes the caller never saw).
  store_nt(writer, observation(2, 80));
  uint64_t unseen = 0;
  size_t len = 0;
  EXPECT_EQ(tahvel_watch(node_, after, kWaitMs, 0, nullptr, &len, &unseen), TAHVEL_INVALID_ARGUMENT);
  EXPECT_EQ(unseen, after);
  EXPECT_NE(std::string(tahvel_last_error()).find("json_out must not be NULL"), std::string::npos) << tahvel_last_error();
  // Nothing comes after the greatest bookmark: it wrapped to 0 and gave the whole board again.
  Text beyond;
  uint64_t last = 0;
  ASSERT_EQ(tahvel_watch(node_, UINT64_MAX, 10, 0, &beyond.data, &beyond.len, &last), TAHVEL_OK);
  EXPECT_EQ(beyond.str(), "");
  EXPECT_EQ(last, UINT64_MAX);
  tahvel_agent_close(writer);
}

TEST_F(CApiTest, ListAsJsonGivesRecordsWithMetadata) {
  tahvel_agent* writer = open_agent("ecg");
  store_nt(writer, observation(1, 72) + observation(2, 80));
  Text json;
  ASSERT_EQ(tahvel_list_as(node_, nullptr, kHeartRate, nullptr, 0, 0, TAHVEL_FORMAT_JSON, &json.data, &json.len),
            TAHVEL_OK);
  const std::string lines = json.str();
  EXPECT_EQ(std::count(lines.begin(), lines.end(), '\n'), 2);
  EXPECT_NE(lines.find("\"persistent\":false"), std::string::npos);
  tahvel_agent_close(writer);
}

}  // namespace
