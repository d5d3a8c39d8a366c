#include "nodes/messages.h"

#include <Eigen/Core>
#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "base/check.h"

namespace procam {
namespace {

static_assert(std::endian::native == std::endian::little,
              "the node protocol is little endian; this build writes host order");

constexpr char kMagic[4] = {'P', 'C', 'N', '2'};

bool CarriesJson(MessageType type) {
  return type == MessageType::kSetup || type == MessageType::kSetupDone ||
         type == MessageType::kPong || type == MessageType::kReady ||
         type == MessageType::kFailed || type == MessageType::kPresented ||
         type == MessageType::kStop;
}

bool KnownType(uint8_t type) {
  return type >= static_cast<uint8_t>(MessageType::kPing) &&
         type <= static_cast<uint8_t>(MessageType::kStop);
}

template <typename T>
void Append(std::string* bytes, const T& value) {
  bytes->append(reinterpret_cast<const char*>(&value), sizeof(T));
}

template <typename T>
T Read(const unsigned char* at) {
  T value;
  std::memcpy(&value, at, sizeof(T));
  return value;
}

uint16_t HalfBits(double value) {
  return Eigen::numext::bit_cast<uint16_t>(Eigen::half(static_cast<float>(value)));
}
double HalfValue(uint16_t bits) {
  return static_cast<double>(static_cast<float>(Eigen::numext::bit_cast<Eigen::half>(bits)));
}

// A kFrame's payload after the header (messages.h): count, scales, binary16 values.
void AppendFrame(const std::vector<double>& emittance, std::string* bytes) {
  const size_t n = emittance.size() / 3;
  double scale[3] = {0.0, 0.0, 0.0};
  for (size_t i = 0; i < emittance.size(); ++i) {
    if (!std::isfinite(emittance[i])) {
      throw std::invalid_argument("frame message: emittance of patch " + std::to_string(i / 3) +
                                  " channel " + std::to_string(i % 3) + " is not finite");
    }
    scale[i % 3] = std::max(scale[i % 3], std::abs(emittance[i]));
  }
  for (int c = 0; c < 3; ++c) {
    if (scale[c] > kMaxFrameScale) {
      throw std::invalid_argument("frame message: channel " + std::to_string(c) +
                                  " reaches an emittance of " + std::to_string(scale[c]) +
                                  " (at most 1e30)");
    }
    if (scale[c] < kMinFrameScale) scale[c] = 0.0;  // sent as zero
  }
  Append(bytes, static_cast<uint32_t>(n));
  Append(bytes, uint32_t{0});
  for (double s : scale) Append(bytes, s);
  const size_t values = bytes->size();
  bytes->resize(values + n * kFramePatchBytes);
  for (size_t i = 0; i < emittance.size(); ++i) {
    const double s = scale[i % 3];
    // The channel's largest value is s itself: its ratio is exactly 1.
    const uint16_t bits = HalfBits(s == 0.0 ? 0.0 : emittance[i] / s);
    std::memcpy(bytes->data() + values + 2 * i, &bits, 2);
  }
}

// The JSON payload of `bytes` [begin, size): an object of at most kMaxTextBytes.
bool ParseJsonPayload(const unsigned char* bytes, size_t begin, size_t size, nlohmann::json* body,
                      std::string* why) {
  const size_t length = size - begin;
  if (length > kMaxTextBytes) {
    return Fail(why, "text payload of " + std::to_string(length) + " bytes (at most " +
                         std::to_string(kMaxTextBytes) + ")");
  }
  *body = nlohmann::json::parse(bytes + begin, bytes + size, nullptr, /*allow_exceptions=*/false);
  if (body->is_discarded())
    return Fail(why, "text payload at offset " + std::to_string(begin) + " is not JSON");
  if (!body->is_object())
    return Fail(why, "text payload at offset " + std::to_string(begin) + " is not a JSON object");
  return true;
}

}  // namespace

const char* MessageTypeName(MessageType type) {
  switch (type) {
    case MessageType::kPing:
      return "ping";
    case MessageType::kPong:
      return "pong";
    case MessageType::kSetup:
      return "setup";
    case MessageType::kSetupDone:
      return "setup-done";
    case MessageType::kFrame:
      return "frame";
    case MessageType::kReady:
      return "ready";
    case MessageType::kPresent:
      return "present";
    case MessageType::kPresented:
      return "presented";
    case MessageType::kFailed:
      return "failed";
    case MessageType::kStop:
      return "stop";
  }
  return "?";
}

std::string EncodeMessage(const Message& message) {
  std::string bytes(kMagic, sizeof(kMagic));
  Append(&bytes, static_cast<uint8_t>(message.type));
  bytes.append(3, '\0');
  Append(&bytes, message.sequence);
  if (message.type == MessageType::kFrame) {
    if (message.emittance.empty() || message.emittance.size() % 3 != 0 ||
        message.emittance.size() / 3 > kMaxFramePatches) {
      throw std::invalid_argument(
          "frame message: emittance of " + std::to_string(message.emittance.size()) +
          " values is not n x 3 with 1 <= n <= " + std::to_string(kMaxFramePatches));
    }
    AppendFrame(message.emittance, &bytes);
    return bytes;
  }
  if (message.type == MessageType::kPresented) Append(&bytes, message.presented_ns);
  if (CarriesJson(message.type)) {
    const nlohmann::json& body = message.body.is_null() ? nlohmann::json::object() : message.body;
    if (!body.is_object()) {
      throw std::invalid_argument(std::string(MessageTypeName(message.type)) +
                                  " message: the payload must be a JSON object");
    }
    const std::string text = body.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
    if (text.size() > kMaxTextBytes) {
      throw std::invalid_argument(std::string(MessageTypeName(message.type)) +
                                  " message: payload of " + std::to_string(text.size()) +
                                  " bytes (at most " + std::to_string(kMaxTextBytes) + ")");
    }
    bytes += text;
  }
  return bytes;
}

using RowMajorEmittance = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

Message FrameMessage(uint64_t frame, const Eigen::MatrixX3d& emittance) {
  Message message;
  message.type = MessageType::kFrame;
  message.sequence = frame;
  message.emittance.resize(emittance.size());
  Eigen::Map<RowMajorEmittance>(message.emittance.data(), emittance.rows(), 3) = emittance;
  return message;
}

Eigen::MatrixX3d FrameEmittance(const Message& frame) {
  return Eigen::Map<const RowMajorEmittance>(frame.emittance.data(),
                                             static_cast<Eigen::Index>(frame.emittance.size() / 3),
                                             3);
}

bool ParseMessage(const void* data, size_t size, Message* message, std::string* why) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  if (size < kMessageHeaderBytes) {
    return Fail(why, "message of " + std::to_string(size) + " bytes, shorter than the " +
                         std::to_string(kMessageHeaderBytes) + "-byte header");
  }
  if (std::memcmp(bytes, kMagic, 3) == 0 && bytes[3] != kMagic[3]) {
    return Fail(why, "a procam node message of another protocol version (magic PCN" +
                         (std::isprint(bytes[3]) ? std::string(1, char(bytes[3])) : "?") +
                         ", this procam speaks PCN2): run the same procam on every PC");
  }
  if (std::memcmp(bytes, kMagic, sizeof(kMagic)) != 0)
    return Fail(why, "not a procam node message (magic)");
  if (!KnownType(bytes[4]))
    return Fail(why, "unknown message type " + std::to_string(int(bytes[4])));
  if (bytes[5] != 0 || bytes[6] != 0 || bytes[7] != 0)
    return Fail(why, "reserved bytes 5-7 are not zero");
  *message = Message();
  message->type = static_cast<MessageType>(bytes[4]);
  message->sequence = Read<uint64_t>(bytes + 8);
  const std::string name = MessageTypeName(message->type);
  size_t offset = kMessageHeaderBytes;
  switch (message->type) {
    case MessageType::kPing:
    case MessageType::kPresent:
      if (size != offset) {
        return Fail(why,
                    name + " message of " + std::to_string(size) + " bytes (carries no payload)");
      }
      return true;
    case MessageType::kFrame: {
      if (size < offset + 8)
        return Fail(why, "frame message of " + std::to_string(size) + " bytes: no patch count");
      const uint32_t patches = Read<uint32_t>(bytes + offset);
      if (Read<uint32_t>(bytes + offset + 4) != 0)
        return Fail(why, "frame message: reserved bytes 20-23 are not zero");
      offset += 8;
      if (patches == 0) return Fail(why, "frame message of 0 patches");
      if (patches > kMaxFramePatches) {
        return Fail(why, "frame message of " + std::to_string(patches) + " patches (at most " +
                             std::to_string(kMaxFramePatches) + ")");
      }
      const size_t expected = kFrameHeadBytes + size_t{patches} * kFramePatchBytes;
      if (size != expected) {
        return Fail(why, "frame message of " + std::to_string(size) + " bytes; " +
                             std::to_string(patches) + " patches need " + std::to_string(expected));
      }
      double scale[3];
      for (int c = 0; c < 3; ++c) {
        scale[c] = Read<double>(bytes + offset + 8 * c);
        if (!(scale[c] == 0.0 || (scale[c] >= kMinFrameScale && scale[c] <= kMaxFrameScale))) {
          return Fail(why, "frame message: channel " + std::to_string(c) + "'s scale " +
                               std::to_string(scale[c]) + " is neither 0 nor in [1e-30, 1e30]");
        }
      }
      offset += 24;
      message->emittance.resize(size_t{patches} * 3);
      double largest[3] = {0.0, 0.0, 0.0};
      for (size_t i = 0; i < message->emittance.size(); ++i) {
        const double h = HalfValue(Read<uint16_t>(bytes + offset + 2 * i));
        if (!std::isfinite(h)) {
          return Fail(why, "frame message: value of patch " + std::to_string(i / 3) + " channel " +
                               std::to_string(i % 3) + " is not finite");
        }
        largest[i % 3] = std::max(largest[i % 3], std::abs(h));
        message->emittance[i] = h * scale[i % 3];
      }
      for (int c = 0; c < 3; ++c) {
        if (largest[c] != (scale[c] == 0.0 ? 0.0 : 1.0)) {
          return Fail(why, "frame message: channel " + std::to_string(c) + "'s largest value is " +
                               std::to_string(largest[c]) + ", not " +
                               (scale[c] == 0.0 ? "0 (its scale is 0)" : "1"));
        }
      }
      return true;
    }
    case MessageType::kPresented:
      if (size < offset + 8)
        return Fail(why, "presented message of " + std::to_string(size) + " bytes: no time");
      message->presented_ns = Read<int64_t>(bytes + offset);
      offset += 8;
      return ParseJsonPayload(bytes, offset, size, &message->body, why);
    case MessageType::kPong:
    case MessageType::kSetup:
    case MessageType::kSetupDone:
    case MessageType::kReady:
    case MessageType::kFailed:
    case MessageType::kStop:
      return ParseJsonPayload(bytes, offset, size, &message->body, why);
  }
  return Fail(why, "unknown message type");
}

}  // namespace procam
