#pragma once
// `procam play`'s remote control over OSC (Open Sound Control 1.0, as show controllers send it:
// QLab, MadMapper, TouchDesigner, lighting desks): the address space, a datagram decoded into a
// message (liblo's decoder), a message checked into a typed command, and the senders allowed.
// Nothing here touches a socket (nodes/osc_server.h does): the fuzz target (fuzz/osc_fuzzer.cc)
// feeds the same two functions every datagram would reach.
//
// The address space (docs/show.md lists it with examples); numbers may be sent as int32 (i),
// float32 (f), double (d) or int64 (h), names as strings (s or S):
//
//   /procam/play                       play from where the show is (after a pause)
//   /procam/pause                      hold the frame shown (fades and method changes go on)
//   /procam/seek SECONDS               go to SECONDS of the source, >= 0
//   /procam/fade LEVEL [SECONDS]       the desired appearance scaled to LEVEL in [0, 1] (0 black,
//                                      1 as made) over SECONDS in [0, 3600] (default 0: at once)
//   /procam/method NAME                naive | reverse | linear | perceptual | perceptual2000
//   /procam/tolerance F                each frame's solve stops below F in [0, 0.1]
//   /procam/surface/NAME CONTENT       the playlist's content CONTENT on surface NAME ("" or
//                                      "none": the surface follows the camera-view source again)
//   /procam/surface NAME CONTENT       the same, for a name an address cannot hold (spaces)
//   /procam/status                     a reply to the sender: /procam/status with frame (i), rate
//                                      (f, frames per second), dropped (i), nodes lost (i),
//                                      source frame (i), paused (i, 0 or 1), fade level (f)
//   /procam/stop                       end the show (result.json written as at the source's end)

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace procam {

// One argument of a decoded message: its OSC type tag and its value (numbers as double, strings
// as text; other tags keep only the tag).
struct OscArgument {
  char type = 0;
  double number = 0.0;
  std::string text;
};

struct OscMessage {
  std::string address;  // e.g. "/procam/fade"
  std::string types;    // the type tags without the leading ',', e.g. "ff"
  std::vector<OscArgument> arguments;
};

// Decodes one OSC datagram (a message, not a bundle) with liblo. False and `*why` (one line, no
// sender: the caller names it) when it is not one.
bool DecodeOscPacket(const uint8_t* data, size_t size, OscMessage* message, std::string* why);

// An OSC message built for sending (replies, tests): `types` one tag per argument of i, f, s.
std::vector<uint8_t> EncodeOscMessage(const OscMessage& message);

struct OscCommand {
  enum class Kind { kPlay, kPause, kSeek, kFade, kMethod, kTolerance, kSurface, kStatus, kStop };
  Kind kind = Kind::kStatus;
  double seconds = 0.0;  // kSeek: the position; kFade: the fade's duration
  double level = 1.0;    // kFade: the level it ends at, [0, 1]
  double tolerance = 0.0;
  std::string method;   // kMethod: a method's name (MethodName)
  std::string surface;  // kSurface: the surface's name
  std::string content;  // kSurface: the playlist's content ("" for none)
  // The command as one line for logs and result.json: "fade 0 1.5", "surface wall clip".
  std::string Text() const;
};

// Checks a message against the address space above: its address, type tags, and every value's
// range (finite numbers, names of the method list, surface names of printable characters). False
// and `*why` (one line naming the address and the argument) otherwise.
bool ParseOscCommand(const OscMessage& message, OscCommand* command, std::string* why);

// Senders the control answers: IPv4 addresses or ranges (127.0.0.1, 192.168.1.0/24).
struct OscAllowList {
  struct Range {
    uint32_t address = 0;  // host order
    int prefix = 32;       // leading bits that must match, [0, 32]
  };
  std::vector<Range> ranges;
  // Parses "A.B.C.D" or "A.B.C.D/N" entries; throws std::invalid_argument naming --osc-allow and
  // the entry.
  static OscAllowList Parse(const std::vector<std::string>& entries);
  bool Allows(uint32_t address) const;  // host order
};

// "A.B.C.D" → host-order address; false if it is not a dotted IPv4 address.
bool ParseIpv4(const std::string& text, uint32_t* address);
std::string Ipv4Text(uint32_t address);

}  // namespace procam
