#pragma once
// The display-node protocol's messages: what a controller and its display nodes send each other
// over ZeroMQ (nodes/transport.h), and the one parser every received message goes through.
//
// Every message is one ZeroMQ frame:
//
//   offset  size  field
//   0       4     magic "PCN2" (procam nodes, protocol version 2; version 1 sent float64)
//   4       1     type (MessageType)
//   5       3     zero
//   8       8     sequence: the frame number (kFrame, kReady, kPresent, kPresented, kFailed), or
//                 the request's number (kPing/kPong, kSetup/kSetupDone), little endian
//   16      ...   payload, by type:
//     kFrame      u32 patches n ≥ 1, u32 zero, 3 float64 scales s_c (R, G, B), then n × 3
//                 IEEE binary16 values h_ic (patch by patch, R G B), little endian: the per-patch
//                 emittance E_ic = h_ic · s_c, 6 bytes a patch (6.2 KiB at 1 000 patches).
//                 s_c is the channel's largest |E_ic| and h_ic = E_ic / s_c rounded to the
//                 nearest binary16, so each value is within 2^-11 of itself (relative; 2^-25 · s_c
//                 absolute near zero): under a fifth of a 10-bit code step for a projector of
//                 gamma 2.2 anywhere in its range (docs/nodes.md). Canonical: a channel's largest
//                 |h_ic| is exactly 1 with s_c in [kMinFrameScale, kMaxFrameScale], or every h_ic is
//                 zero with s_c = 0, so that a parsed frame encodes again to the same bytes.
//     kPresented  i64 the presentation time (ns since the Unix epoch, the node's system clock,
//                 which linuxptp keeps in step between PCs), then kPong's JSON
//     kSetup, kSetupDone, kPong, kReady, kFailed, kStop
//                 a JSON object, UTF-8, at most kMaxTextBytes
//     kPing, kPresent
//                 nothing
//
// The order of one frame k (the frame barrier): the controller sends kFrame k to every node;
// each renders its projectors' images into the windows' back buffers and answers kReady k; when
// every live node is ready the controller sends kPresent k; each node swaps its windows and
// answers kPresented k with the time of the swap. A node never shows frame k+1 before every node
// has shown k, since its kReady k+1 follows its own kPresented k and kPresent k+1 waits for every
// kReady k+1.
//
// ParseMessage takes any bytes (from a peer that may be broken or hostile: the transport lets
// only the rig's controller in, but a parser must not rely on that): it checks the size of every
// field against the message's length before reading it and refuses, with one line, anything
// that is not exactly a message of this protocol. It never throws and never reads past `size`.

#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace procam {

enum class MessageType : uint8_t {
  kPing = 1,       // controller → node: are you there (answered by kPong)
  kPong = 2,       // node → controller: its status (name, projectors, monitors, render device)
  kSetup = 3,      // controller → node: the rig to render (scene, patches, options)
  kSetupDone = 4,  // node → controller: the rig is built (or why not: "error")
  kFrame = 5,      // controller → node: per-patch emittance of frame `sequence`
  kReady = 6,      // node → controller: frame `sequence` is rendered into the back buffers
  kPresent = 7,    // controller → node: show frame `sequence`
  kPresented = 8,  // node → controller: frame `sequence` is on its monitors, and when
  kFailed = 9,     // node → controller: something went wrong (a monitor gone, a bad frame)
  kStop = 10,      // controller → node: the show is over ({"exit": true}: the node returns)
};
const char* MessageTypeName(MessageType type);

constexpr size_t kMessageHeaderBytes = 16;
constexpr size_t kMaxTextBytes = 64 * 1024;
// Patches a kFrame may carry: 4 million (a message of 24 MiB), past any room procam solves.
constexpr uint32_t kMaxFramePatches = 1u << 22;
// A kFrame's bytes before its values (header, count, scales) and per patch.
constexpr size_t kFrameHeadBytes = kMessageHeaderBytes + 8 + 3 * 8;
constexpr size_t kFramePatchBytes = 3 * 2;
// The range of a channel's non-zero scale: a channel whose largest |E| is below kMinFrameScale is
// sent as zero (no projector's light is that small in any unit procam uses); one above
// kMaxFrameScale is refused.
constexpr double kMinFrameScale = 1e-30, kMaxFrameScale = 1e30;
// What the transport lets through at most (ZMQ_MAXMSGSIZE): a kFrame of kMaxFramePatches.
constexpr int64_t kMaxMessageBytes =
    int64_t{kFrameHeadBytes} + int64_t{kFramePatchBytes} * kMaxFramePatches;

struct Message {
  MessageType type = MessageType::kPing;
  uint64_t sequence = 0;
  // kFrame: n × 3, row-major (patch, channel). Parsed: the values the frame carries (h_ic · s_c);
  // to encode: any, rounded by the encoder.
  std::vector<double> emittance;
  int64_t presented_ns = 0;       // kPresented
  nlohmann::json body;            // the JSON payload of the types that carry one; else null
};

// The bytes of `message` (its type decides which fields are written; a kFrame's emittance rounded
// as above). Throws std::invalid_argument if a kFrame's emittance is not n × 3 with
// n ≤ kMaxFramePatches, is not finite or has a channel larger than kMaxFrameScale, or a JSON
// payload is not an object or longer than kMaxTextBytes.
std::string EncodeMessage(const Message& message);

// A kFrame numbered `frame` carrying `emittance` (n,3), and a parsed kFrame's emittance as an
// (n,3) matrix (n = emittance.size() / 3).
Message FrameMessage(uint64_t frame, const Eigen::MatrixX3d& emittance);
Eigen::MatrixX3d FrameEmittance(const Message& frame);

// Parses one received message. False with `why` set (one line: what is wrong, at which offset)
// for anything malformed: short, wrong magic or type (another protocol version named as such),
// non-zero reserved bytes, a payload of the wrong size for its type or its patch count, a frame
// that is not canonical (a scale out of range, a value not finite, a channel whose largest value
// is not 1), text that is not a JSON object. `message` is unspecified when false.
bool ParseMessage(const void* data, size_t size, Message* message, std::string* why);

}  // namespace procam
