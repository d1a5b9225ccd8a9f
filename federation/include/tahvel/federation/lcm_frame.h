// One Frame as one LCM message: a tahvel_frame_t (federation/types/tahvel_frame.lcm) as lcm-gen
// lays it out. Pure (no socket), so that tests and the fuzz target feed it bytes; the LCM
// binding (docs/transports.md) sends and takes frames through it.
#pragma once

#include <string>
#include <string_view>

#include "tahvel/federation/transport.h"
#include "tahvel/node/error.h"

namespace tahvel::federation {

// The message's bytes. Fails (invalid_argument) only for a frame LCM's types cannot carry: a
// message of 2 GB or more, or an IRI with a NUL in it (LCM's strings end at their first NUL).
node::Result<std::string> encode_lcm_frame(const Frame& frame);

// The frame `message` holds, or why it holds none (invalid_argument; the message says what is
// wrong and where, e.g. "not a tahvel_frame_t ('body' says -1 bytes, 3 are left)"). Every length
// is checked before lcm-gen's decoder reads it: that decoder hands a negative length to malloc
// and memcpy and reads a string without its NUL past its end. The frame is decoded only, not
// judged: its version, fingerprint and addressee are the caller's to check (wire.h).
node::Result<Frame> decode_lcm_frame(std::string_view message);

}  // namespace tahvel::federation
