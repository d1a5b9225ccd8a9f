// Bodies of link frames (docs/protocol.md, "Bodies"): items, records, queries and errors in a
// compact binary form — the hot path (items up) costs no RDF parsing. Integers are little-endian,
// strings are u32 length + bytes. Decoders name the field and byte offset that is wrong.
// Public so that tools outside the library can read and write frames' bodies as a link does (a
// protocol analyser; tests/fuzz/fuzz_wire.cpp).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tahvel/federation/transport.h"
#include "tahvel/node/node.h"

namespace tahvel::federation::wire {

// An item travelling up or down: the triples and what the receiving node keeps of the sender's
// metadata (the source, context, asserted-at time and persistence).
struct ItemBody {
  std::string source;
  node::Item item;
  // A removal notice (P7a): `item` holds the records removed on the sender, with the context and
  // asserted-at time of the item they were in; the receiver removes its copies of them.
  bool removal = false;
  std::vector<std::uint32_t> positions;  // a notice's: each triple's position in its item
};
std::string encode_item(const ItemBody& body);
Result<ItemBody> decode_item(std::string_view bytes);

// A remote query (frame kind query; frame.seq is the query id at its origin).
struct QueryBody {
  std::string origin;    // IRI of the node where the operator asked
  std::string target;    // IRI of the node that answers
  std::optional<node::Term> s, p, o;
  std::optional<std::int64_t> since, until;
  std::uint32_t cascade = 0;
  std::uint64_t limit = 0;
  std::string area;                // a room IRI or WKT; empty: no area (link.h AreaQuery)
  std::optional<std::int64_t> floor;
  // Since version 4 (node::Pattern::source, ::under); empty: none.
  std::string source;  // written by this agent or node, or one below it
  std::string under;   // subject is this IRI or one below it
};
// `version`: the frame's protocol version; before 4 a query has no source nor under, and
// encoding one that has either is refused (the caller tells the asker instead).
Result<std::string> encode_query(const QueryBody& body, std::uint16_t version = kProtocolVersion);
Result<QueryBody> decode_query(std::string_view bytes, std::uint16_t version = kProtocolVersion);

// One chunk of an answer (frame kind answer): the origin, records with their metadata, and
// whether it is the last chunk.
struct AnswerBody {
  std::string origin;
  bool last = false;
  std::vector<node::Record> records;
};
// `version`: the frame's protocol version; before 3 a record has no span.
std::string encode_answer(const AnswerBody& body, std::uint16_t version = kProtocolVersion);
Result<AnswerBody> decode_answer(std::string_view bytes, std::uint16_t version = kProtocolVersion);

// A refusal or failure (frame kind error): a stable code and a message. For a query, frame.seq
// is the query id and the body also names the origin.
struct ErrorBody {
  std::string code;  // refused, unregistered, unknown_node, unreachable, query_failed, cancelled,
                    // link_restarted
  std::string message;
  std::string origin;
};
std::string encode_error(const ErrorBody& body);
Result<ErrorBody> decode_error(std::string_view bytes);

// How full a child's store is, as its hellos and heartbeats say since protocol version 5
// (docs/protocol.md P12): its parent shows it, so that a store that refuses its agents' writes
// is seen from above, where the data it stops making is missed.
struct StoreRoom {
  std::uint64_t used_bytes = 0;       // up to the last page in use (node::Stats::high_water_bytes)
  std::uint64_t data_bytes = 0;       // pages holding data (node::Stats::used_bytes)
  std::uint64_t max_bytes = 0;        // the most it may use (node::Stats::max_map_bytes)
  std::uint64_t disk_free_bytes = 0;  // free to it on the disk that holds it
  bool operator==(const StoreRoom&) const = default;
};

// Hello (child -> parent), welcome (parent -> child) and heartbeat bodies: the sender's
// software version and state, and for hello and welcome the store ids that name the streams
// (docs/protocol.md P6a).
struct StateBody {
  std::string software_version;
  std::uint64_t outbox_depth = 0;  // in a welcome: the last item of the child's down queue (P6f)
  std::string store_id;       // the sender's store (node::Node::store_id)
  std::string peer_store_id;  // hello: the parent's store that the child's down mark counts in
  std::optional<StoreRoom> room;  // a child's hello and heartbeat, from version 5
};
std::string encode_state(const StateBody& body);
// `version`: the frame's; a body of an earlier version has no room, and bytes where it would
// be are left over.
Result<StateBody> decode_state(std::string_view bytes, std::uint16_t version = kProtocolVersion);

}  // namespace tahvel::federation::wire
