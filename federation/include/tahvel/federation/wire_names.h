// Where a frame for a given IRI travels on the wire: the LCM channel and the DDS topic that the
// endpoint bound to that IRI listens on (docs/transports.md). Useful to tools that watch the
// wire (lcm-spy, cyclonedds ps) and to tests that put raw bytes there.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace tahvel::federation {

// 64-bit FNV-1a of the IRI's bytes, as used by both names below. Two IRIs may share a hash;
// each binding therefore also checks Frame::to on receipt.
std::uint64_t wire_hash(std::string_view iri) noexcept;

// "TV" + 16 lower-case hex digits of wire_hash(iri): 18 characters, well under LCM's channel
// name limit of 63, whatever the IRI's length.
std::string lcm_channel(std::string_view iri);

// "tahvel_frame_" + 16 lower-case hex digits of wire_hash(iri): a valid DDS topic name for any
// IRI (IRIs contain characters DDS topic names may not).
std::string dds_topic(std::string_view iri);

}  // namespace tahvel::federation
