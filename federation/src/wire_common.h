// What the wire bindings (transport_lcm.cpp, transport_dds.cpp) share: the checks on a frame
// before it is sent and after it is received, and the wording of drop lines.
#pragma once

#include <chrono>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tahvel/federation/transport.h"

namespace tahvel::federation::wire {

// The largest body a wire binding accepts in send(). LCM and DDS both fragment; this bound keeps
// one frame's reassembly buffers (sender, network stack, receiver) at a size a gateway can hold.
// The link splits anything larger.
inline constexpr std::size_t kMaxBody = 64u << 20;

// True for the kinds FrameKind names (1..9).
bool known_kind(std::uint8_t kind) noexcept;

// `text` made safe for a one-line log: control and non-ASCII bytes as \xNN, cut at `max` bytes.
std::string printable(std::string_view text, std::size_t max = 160);

// `text` as one line of a log, whole: control bytes (C0, DEL, C1) and bytes that are not
// well-formed UTF-8 as \xNN, other UTF-8 kept (a node's IRI may be "…/kotiä"). For lines that
// carry what a peer sent: a forged IRI must not add a line of its own, or move a terminal's cursor.
std::string one_line(std::string_view text);

// "kind 3 seq 5 from <iri> to <iri>" for log lines.
std::string describe(const Frame& frame);

// Why `frame` may not be sent by the endpoint `self` of `binding` ("dds", "lcm"): an IRI with a
// NUL byte, an empty `to`, a body over kMaxBody; or success. Runs on every send, so the message
// is made only on failure.
Result<void> check_sendable(const Frame& frame, std::string_view binding, std::string_view self);

// Why a decoded frame received by the endpoint `self` must be dropped: frame_refusal (another
// protocol version, another message fingerprint, addressed to another IRI), or a kind outside
// FrameKind (which the generated decoders, unlike decode_frame, let through); nullopt when good.
std::optional<std::string> reject_reason(const Frame& frame, std::string_view self);

// Packing (docs/transports.md): the frames of a run, all from one sender to one addressee, in
// the body of one sample of kind kPackedKind. Per frame, little-endian: u8 kind, u64 seq, u64
// prev, u64 ack, u32 body length, the body.
inline constexpr std::size_t kPackedFrameHeader = 1 + 8 + 8 + 8 + 4;
void append_packed(std::string& pack, const Frame& frame);

// The frames packed in the body of `sample`, each with the sample's version, fingerprint, from
// and to. Decoding is strict (P17): at the first frame that does not decode the rest of the
// sample is dropped, and `error` says where and why; it is left empty when all decoded.
std::vector<Frame> unpack(const Frame& sample, std::string& error);

// `log`, or a sink that writes the line to stderr when `log` is empty (the DropLog default).
DropLog or_stderr(DropLog log);

// `log`, saying at most kDropLinesPerWindow lines per kDropLogWindow (P4): a sender of junk
// must not fill the log and push out what it held. The lines left out are counted, and the
// count is said with the next line said after the window.
inline constexpr std::size_t kDropLinesPerWindow = 10;
inline constexpr std::chrono::seconds kDropLogWindow{10};
DropLog rate_limited(DropLog log);

}  // namespace tahvel::federation::wire
