#include "nodes/osc.h"

#include <fmt/format.h>
#include <lo/lo.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <stdexcept>

namespace procam {
namespace {

constexpr const char* kPrefix = "/procam/";
constexpr size_t kMaxName = 128;  // surface and content names, characters

std::string LibloError(int code) {
  switch (code) {
    case LO_ENOPATH:
    case LO_EINVALIDPATH:
      return "no valid address";
    case LO_ENOTYPE:
    case LO_EINVALIDTYPE:
    case LO_EBADTYPE:
      return "no valid type tags";
    case LO_ESIZE:
    case LO_EPAD:
    case LO_ETERM:
      return "its length does not fit its arguments";
    case LO_EINVALIDARG:
      return "an argument that is not valid";
    default:
      return fmt::format("liblo error {}", code);
  }
}

bool IsNumber(char type) { return type == 'i' || type == 'f' || type == 'd' || type == 'h'; }
bool IsText(char type) { return type == 's' || type == 'S'; }

// A name sent by a controller: printable ASCII, not empty unless `may_be_empty`, bounded.
bool CheckName(const std::string& name, bool may_be_empty, const std::string& what,
               std::string* why) {
  if (name.empty() && !may_be_empty) {
    *why = what + " is empty";
    return false;
  }
  if (name.size() > kMaxName) {
    *why = fmt::format("{} is longer than {} characters", what, kMaxName);
    return false;
  }
  for (unsigned char c : name) {
    if (c < 0x20 || c > 0x7e) {
      *why = fmt::format("{} holds a character that is not printable ASCII (code {})", what,
                         static_cast<int>(c));
      return false;
    }
  }
  return true;
}

// `text` as one line of printable ASCII: other bytes written as \xNN (an address or a type tag a
// sender made up must not break the log's one line per refusal).
std::string Printable(const std::string& text) {
  std::string out;
  for (unsigned char c : text) {
    if (c >= 0x20 && c < 0x7f && c != '\\') {
      out += static_cast<char>(c);
    } else {
      out += fmt::format("\\x{:02x}", c);
    }
  }
  return out;
}

bool Parse(const OscMessage& message, OscCommand* command, std::string* why);

}  // namespace

bool ParseOscCommand(const OscMessage& message, OscCommand* command, std::string* why) {
  if (Parse(message, command, why)) return true;
  *why = Printable(*why);
  return false;
}

bool DecodeOscPacket(const uint8_t* data, size_t size, OscMessage* message, std::string* why) {
  *message = OscMessage();
  if (size == 0) {
    *why = "an empty datagram";
    return false;
  }
  if (size >= 8 && std::memcmp(data, "#bundle", 8) == 0) {
    *why = "an OSC bundle (send the messages one by one)";
    return false;
  }
  if (data[0] != '/') {
    *why = "not an OSC message (its address does not start with '/')";
    return false;
  }
  // liblo's decoder takes a writable buffer; it checks the address, the type tags, the padding
  // and every argument's length against the datagram's.
  std::vector<uint8_t> copy(data, data + size);
  int result = 0;
  const std::unique_ptr<std::remove_pointer_t<lo_message>, void (*)(lo_message)> decoded(
      lo_message_deserialise(copy.data(), copy.size(), &result), lo_message_free);
  if (decoded == nullptr) {
    *why = "not an OSC message: " + LibloError(result);
    return false;
  }
  message->address.assign(reinterpret_cast<const char*>(data),
                          strnlen(reinterpret_cast<const char*>(data), size));
  const char* types = lo_message_get_types(decoded.get());
  const int count = lo_message_get_argc(decoded.get());
  lo_arg** values = lo_message_get_argv(decoded.get());
  message->types = types != nullptr ? types : "";
  if (static_cast<int>(message->types.size()) != count) {
    *why = "not an OSC message: its type tags do not count its arguments";
    return false;
  }
  // liblo's argument pointers lie inside the datagram, at 4-byte offsets: an 8-byte value
  // ('d', 'h') is read by bytes, never through lo_arg's (8-byte aligned) union.
  const auto read = [&](int k, auto* value) {
    std::memcpy(value, reinterpret_cast<const unsigned char*>(values[k]), sizeof(*value));
  };
  for (int k = 0; k < count; ++k) {
    OscArgument argument;
    argument.type = message->types[k];
    switch (argument.type) {
      case 'i': {
        int32_t value = 0;
        read(k, &value);
        argument.number = value;
        break;
      }
      case 'f': {
        float value = 0;
        read(k, &value);
        argument.number = value;
        break;
      }
      case 'd': {
        double value = 0;
        read(k, &value);
        argument.number = value;
        break;
      }
      case 'h': {
        int64_t value = 0;
        read(k, &value);
        argument.number = static_cast<double>(value);
        break;
      }
      case 's':
      case 'S':
        argument.text = reinterpret_cast<const char*>(values[k]);
        break;
      default:
        break;  // the tag alone: the command's check refuses what it does not take
    }
    message->arguments.push_back(std::move(argument));
  }
  return true;
}

std::vector<uint8_t> EncodeOscMessage(const OscMessage& message) {
  const std::unique_ptr<std::remove_pointer_t<lo_message>, void (*)(lo_message)> encoded(
      lo_message_new(), lo_message_free);
  for (const OscArgument& argument : message.arguments) {
    switch (argument.type) {
      case 'i':
        lo_message_add_int32(encoded.get(), static_cast<int32_t>(argument.number));
        break;
      case 'f':
        lo_message_add_float(encoded.get(), static_cast<float>(argument.number));
        break;
      case 's':
        lo_message_add_string(encoded.get(), argument.text.c_str());
        break;
      default:
        throw std::invalid_argument(
            fmt::format("EncodeOscMessage: type '{}' is not one of i, f, s", argument.type));
    }
  }
  size_t size = 0;
  void* bytes = lo_message_serialise(encoded.get(), message.address.c_str(), nullptr, &size);
  if (bytes == nullptr)
    throw std::invalid_argument("EncodeOscMessage: liblo cannot encode " + message.address);
  std::vector<uint8_t> out(static_cast<uint8_t*>(bytes), static_cast<uint8_t*>(bytes) + size);
  std::free(bytes);
  return out;
}

std::string OscCommand::Text() const {
  switch (kind) {
    case Kind::kPlay:
      return "play";
    case Kind::kPause:
      return "pause";
    case Kind::kSeek:
      return fmt::format("seek {:g}", seconds);
    case Kind::kFade:
      return fmt::format("fade {:g} {:g}", level, seconds);
    case Kind::kMethod:
      return "method " + method;
    case Kind::kTolerance:
      return fmt::format("tolerance {:g}", tolerance);
    case Kind::kSurface:
      return "surface " + surface + " " + (content.empty() ? "none" : content);
    case Kind::kStatus:
      return "status";
    case Kind::kStop:
      return "stop";
  }
  return "";
}

namespace {

bool Parse(const OscMessage& message, OscCommand* command, std::string* why) {
  *command = OscCommand();
  const std::string& address = message.address;
  const std::string where = address.substr(0, kMaxName);  // bounded in the line it goes to
  if (!address.starts_with(kPrefix)) {
    *why = where + ": not an address of procam's (/procam/...)";
    return false;
  }
  if (message.types.size() != message.arguments.size()) {
    *why = where + ": type tags and arguments differ in number";
    return false;
  }
  const std::string name = address.substr(std::strlen(kPrefix));
  const std::vector<OscArgument>& args = message.arguments;
  // The number of arguments in [min, max], each checked by the caller.
  auto count = [&](size_t min, size_t max) {
    if (args.size() >= min && args.size() <= max) return true;
    *why = min == max
               ? fmt::format("{}: takes {} argument(s), got {}", where, min, args.size())
               : fmt::format("{}: takes {} to {} arguments, got {}", where, min, max, args.size());
    return false;
  };
  // Argument k a finite number in [min, max].
  auto number = [&](size_t k, const char* what, double min, double max, double* value) {
    const OscArgument& arg = args[k];
    if (!IsNumber(arg.type)) {
      *why = fmt::format("{}: argument {} ({}) must be a number (i, f, d or h), got type '{}'",
                         where, k + 1, what, arg.type);
      return false;
    }
    if (!std::isfinite(arg.number) || arg.number < min || arg.number > max) {
      *why = fmt::format("{}: argument {} ({}) must be in [{}, {}], got {}", where, k + 1, what,
                         min, max, arg.number);
      return false;
    }
    *value = arg.number;
    return true;
  };
  auto text = [&](size_t k, const char* what, std::string* value) {
    const OscArgument& arg = args[k];
    if (!IsText(arg.type)) {
      *why = fmt::format("{}: argument {} ({}) must be a string (s), got type '{}'", where, k + 1,
                         what, arg.type);
      return false;
    }
    *value = arg.text;
    return true;
  };
  using Kind = OscCommand::Kind;
  if (name == "play" || name == "pause" || name == "status" || name == "stop") {
    if (!count(0, 0)) return false;
    command->kind = name == "play"    ? Kind::kPlay
                    : name == "pause" ? Kind::kPause
                    : name == "stop"  ? Kind::kStop
                                      : Kind::kStatus;
    return true;
  }
  if (name == "seek") {
    command->kind = Kind::kSeek;
    return count(1, 1) && number(0, "seconds", 0.0, 1e7, &command->seconds);
  }
  if (name == "fade") {
    command->kind = Kind::kFade;
    if (!count(1, 2) || !number(0, "level", 0.0, 1.0, &command->level)) return false;
    command->seconds = 0.0;
    return args.size() < 2 || number(1, "seconds", 0.0, 3600.0, &command->seconds);
  }
  if (name == "method") {
    command->kind = Kind::kMethod;
    if (!count(1, 1) || !text(0, "method", &command->method)) return false;
    for (const char* known : {"naive", "reverse", "linear", "perceptual", "perceptual2000"})
      if (command->method == known) return true;
    std::string shown;
    if (!CheckName(command->method, false, "the method", &shown)) {
      *why = where + ": " + shown;
      return false;
    }
    *why = where +
           ": argument 1 (method) must be naive, reverse, linear, perceptual or "
           "perceptual2000, got '" +
           command->method + "'";
    return false;
  }
  if (name == "tolerance") {
    command->kind = Kind::kTolerance;
    return count(1, 1) && number(0, "tolerance", 0.0, 0.1, &command->tolerance);
  }
  if (name == "surface" || name.starts_with("surface/")) {
    command->kind = Kind::kSurface;
    // /procam/surface/NAME CONTENT, or /procam/surface NAME CONTENT (a name OSC addresses
    // cannot hold, e.g. with a space).
    const bool in_address = name != "surface";
    std::string problem;
    if (in_address) {
      command->surface = name.substr(std::strlen("surface/"));
      if (!count(1, 1) || !text(0, "content", &command->content)) return false;
    } else if (!count(2, 2) || !text(0, "surface", &command->surface) ||
               !text(1, "content", &command->content)) {
      return false;
    }
    if (!CheckName(command->surface, false, "the surface's name", &problem) ||
        (in_address && command->surface.find('/') != std::string::npos)) {
      *why = where + ": " + (problem.empty() ? "the surface's name holds '/'" : problem);
      return false;
    }
    if (!CheckName(command->content, true, "the content's name", &problem)) {
      *why = where + ": " + problem;
      return false;
    }
    if (command->content == "none") command->content.clear();
    return true;
  }
  *why = where + ": no such address (docs/show.md lists them)";
  return false;
}

}  // namespace

bool ParseIpv4(const std::string& text, uint32_t* address) {
  uint32_t value = 0;
  int parts = 0;
  size_t k = 0;
  while (parts < 4) {
    if (k >= text.size() || text[k] < '0' || text[k] > '9') return false;
    int part = 0, digits = 0;
    while (k < text.size() && text[k] >= '0' && text[k] <= '9') {
      part = part * 10 + (text[k] - '0');
      if (++digits > 3 || part > 255) return false;
      ++k;
    }
    value = (value << 8) | static_cast<uint32_t>(part);
    ++parts;
    if (parts < 4) {
      if (k >= text.size() || text[k] != '.') return false;
      ++k;
    }
  }
  if (k != text.size()) return false;
  *address = value;
  return true;
}

std::string Ipv4Text(uint32_t address) {
  return fmt::format("{}.{}.{}.{}", address >> 24, (address >> 16) & 255, (address >> 8) & 255,
                     address & 255);
}

OscAllowList OscAllowList::Parse(const std::vector<std::string>& entries) {
  OscAllowList list;
  for (const std::string& entry : entries) {
    Range range;
    const size_t slash = entry.find('/');
    const std::string host = entry.substr(0, slash);
    bool ok = ParseIpv4(host, &range.address);
    if (ok && slash != std::string::npos) {
      const std::string bits = entry.substr(slash + 1);
      ok = !bits.empty() && bits.size() <= 2 &&
           bits.find_first_not_of("0123456789") == std::string::npos;
      if (ok) range.prefix = std::stoi(bits);
      ok = ok && range.prefix <= 32;
    }
    if (!ok) {
      throw std::invalid_argument("--osc-allow: '" + entry +
                                  "' is not an IPv4 address or range (A.B.C.D or A.B.C.D/N)");
    }
    list.ranges.push_back(range);
  }
  return list;
}

bool OscAllowList::Allows(uint32_t address) const {
  for (const Range& range : ranges) {
    const uint32_t mask = range.prefix == 0 ? 0u : ~0u << (32 - range.prefix);
    if ((address & mask) == (range.address & mask)) return true;
  }
  return false;
}

}  // namespace procam
