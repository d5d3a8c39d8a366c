#pragma once
// The display-node protocol's messages: what a controller and its display nodes send each other
// over ZeroMQ (nodes/transport.h), and the one parser every received message goes through.
//
// Every message is one ZeroMQ frame:
//
//   offset  size  field
//   0       4     magic "PCN1" (procam nodes, protocol version 1)
//   4       1     type (MessageType)
//   5       3     zero
//   8       8     sequence: the frame number (kFrame, kReady, kPresent, kPresented, kFailed), or
//                 the request's number (kPing/kPong, kSetup/kSetupDone), little endian
//   16      ...   payload, by type:
//     kFrame      u32 patches n ≥ 1, u32 zero, then n × 3 float64 per-patch emittance (R, G,
//                 B), little endian: exactly what the solver computed (24 bytes a patch)
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
// Patches a kFrame may carry: 4 million (a message of 96 MiB), past any room procam solves.
constexpr uint32_t kMaxFramePatches = 1u << 22;
// What the transport lets through at most (ZMQ_MAXMSGSIZE): a kFrame of kMaxFramePatches.
constexpr int64_t kMaxMessageBytes =
    int64_t{kMessageHeaderBytes} + 8 + int64_t{24} * kMaxFramePatches;

struct Message {
  MessageType type = MessageType::kPing;
  uint64_t sequence = 0;
  std::vector<double> emittance;  // kFrame: n × 3, row-major (patch, channel)
  int64_t presented_ns = 0;       // kPresented
  nlohmann::json body;            // the JSON payload of the types that carry one; else null
};

// The bytes of `message` (its type decides which fields are written). Throws
// std::invalid_argument if a kFrame's emittance is not n × 3 with n ≤ kMaxFramePatches, or a JSON
// payload is not an object or longer than kMaxTextBytes.
std::string EncodeMessage(const Message& message);

// Parses one received message. False with `why` set (one line: what is wrong, at which offset)
// for anything malformed: short, wrong magic or type, non-zero reserved bytes, a payload of the
// wrong size for its type or its patch count, non-finite emittance, text that is not a JSON
// object. `message` is unspecified when false.
bool ParseMessage(const void* data, size_t size, Message* message, std::string* why);

}  // namespace procam
