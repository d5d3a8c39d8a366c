// The display-node protocol's encoder and parser: every type round-trips, and anything that is
// not exactly a message is refused with one line, without reading past its end.
#include "nodes/messages.h"

#include <gtest/gtest.h>

#include <cmath>
#include <algorithm>
#include <cstring>
#include <limits>
#include <random>

namespace procam {
namespace {

Message Parsed(const std::string& bytes) {
  Message message;
  std::string why;
  EXPECT_TRUE(ParseMessage(bytes.data(), bytes.size(), &message, &why)) << why;
  return message;
}

std::string Refusal(const std::string& bytes) {
  Message message;
  std::string why;
  EXPECT_FALSE(ParseMessage(bytes.data(), bytes.size(), &message, &why))
      << "accepted " << bytes.size() << " bytes";
  EXPECT_FALSE(why.empty());
  EXPECT_EQ(why.find('\n'), std::string::npos) << why;
  return why;
}

TEST(NodeMessages, EveryTypeRoundTrips) {
  Message frame;
  frame.type = MessageType::kFrame;
  frame.sequence = 0x0123456789abcdefULL;
  // Binary16 values times the channel's largest |E| (3, 1.125, 2.25) come back exactly.
  frame.emittance = {0.0, 1.125, -2.25, 3.0, 0.5625, 0.5625};
  const std::string bytes = EncodeMessage(frame);
  EXPECT_EQ(bytes.size(), kMessageHeaderBytes + 8 + 3 * 8 + 2 * 3 * 2);  // messages.h's layout
  EXPECT_EQ(bytes.substr(0, 4), "PCN2");
  const Message back = Parsed(bytes);
  EXPECT_EQ(back.type, MessageType::kFrame);
  EXPECT_EQ(back.sequence, frame.sequence);
  EXPECT_EQ(back.emittance, frame.emittance);
  EXPECT_EQ(EncodeMessage(back), bytes);  // canonical: a parsed frame encodes to the same bytes
  // The same frame from and back to an (n,3) matrix, patch by patch.
  Eigen::MatrixX3d matrix(2, 3);
  matrix << 0.0, 1.125, -2.25, 3.0, 0.5625, 0.5625;
  EXPECT_EQ(FrameMessage(frame.sequence, matrix).emittance, frame.emittance);
  EXPECT_EQ(FrameEmittance(back), matrix);

  for (MessageType type : {MessageType::kPong, MessageType::kSetup, MessageType::kSetupDone,
                           MessageType::kReady, MessageType::kFailed, MessageType::kStop}) {
    Message message;
    message.type = type;
    message.sequence = 42;
    message.body = {{"node", "left"}, {"render_ms", 1.25}, {"text", "é ✓"}};
    const Message parsed = Parsed(EncodeMessage(message));
    EXPECT_EQ(parsed.type, type);
    EXPECT_EQ(parsed.sequence, 42u);
    EXPECT_EQ(parsed.body, message.body) << MessageTypeName(type);
  }
  Message presented;
  presented.type = MessageType::kPresented;
  presented.sequence = 7;
  presented.presented_ns = 1795579740307122664LL;
  presented.body = {{"node", "n1"}};
  const Message parsed = Parsed(EncodeMessage(presented));
  EXPECT_EQ(parsed.presented_ns, presented.presented_ns);
  EXPECT_EQ(parsed.body, presented.body);
  for (MessageType type : {MessageType::kPing, MessageType::kPresent}) {
    Message message;
    message.type = type;
    EXPECT_EQ(EncodeMessage(message).size(), kMessageHeaderBytes);
    EXPECT_EQ(Parsed(EncodeMessage(message)).type, type);
  }
}

// A frame's values are the emittance rounded to binary16 relative to the channel's largest: IEEE
// binary16 has 11 significant bits, so each value is within 2^-11 of itself (relative), or of
// 2^-25 times the channel's largest below binary16's normal range (its subnormals step by 2^-24).
TEST(NodeMessages, AFrameCarriesTheEmittanceWithinHalfPrecision) {
  std::mt19937 random(11);
  std::uniform_real_distribution<double> exponent(-9.0, 0.0), sign(-1.0, 1.0);
  Message frame;
  frame.type = MessageType::kFrame;
  const int n = 5000;
  for (int i = 0; i < 3 * n; ++i) {
    // Channels of different units: up to 1.6, 2e-4 and 3e6.
    const double unit = i % 3 == 0 ? 1.6 : i % 3 == 1 ? 2e-4 : 3e6;
    frame.emittance.push_back(unit * std::pow(10.0, exponent(random)) * (sign(random) < 0 ? -1 : 1));
  }
  frame.emittance[4] = 0.0;
  const std::string bytes = EncodeMessage(frame);
  EXPECT_EQ(bytes.size(), kFrameHeadBytes + size_t{6} * n);
  const Message back = Parsed(bytes);
  ASSERT_EQ(back.emittance.size(), frame.emittance.size());
  double largest[3] = {0, 0, 0};
  for (size_t i = 0; i < frame.emittance.size(); ++i)
    largest[i % 3] = std::max(largest[i % 3], std::abs(frame.emittance[i]));
  double worst = 0.0;  // the largest relative error over the normal range
  for (size_t i = 0; i < frame.emittance.size(); ++i) {
    const double e = frame.emittance[i], error = std::abs(back.emittance[i] - e);
    ASSERT_LE(error, std::ldexp(std::abs(e), -11) + std::ldexp(largest[i % 3], -25)) << i;
    if (std::abs(e) >= std::ldexp(largest[i % 3], -14)) worst = std::max(worst, error / std::abs(e));
  }
  EXPECT_EQ(back.emittance[4], 0.0);
  // Rounded, not truncated or kept: the worst error is close to the bound.
  EXPECT_GT(worst, std::ldexp(1.0, -12));
  EXPECT_EQ(EncodeMessage(back), bytes);
  // A channel whose largest |E| is under 1e-30 is sent as zero; one over 1e30 is refused.
  frame.emittance = {1.0, 5e-31, 2.0};
  EXPECT_EQ(Parsed(EncodeMessage(frame)).emittance, (std::vector<double>{1.0, 0.0, 2.0}));
  frame.emittance = {1.0, 2e30, 2.0};
  EXPECT_THROW(EncodeMessage(frame), std::invalid_argument);
  frame.emittance = {1.0, std::numeric_limits<double>::infinity(), 2.0};
  EXPECT_THROW(EncodeMessage(frame), std::invalid_argument);
}

TEST(NodeMessages, MalformedMessagesAreRefusedWithOneLine) {
  Message frame;
  frame.type = MessageType::kFrame;
  frame.sequence = 3;
  frame.emittance = {1.0, 2.0, 3.0, 4.0, 5.0, 6.0};
  const std::string good = EncodeMessage(frame);

  EXPECT_NE(Refusal("").find("shorter than"), std::string::npos);
  EXPECT_NE(Refusal(good.substr(0, 15)).find("shorter than"), std::string::npos);
  std::string bad = good;
  bad[0] = 'X';
  EXPECT_NE(Refusal(bad).find("magic"), std::string::npos);
  bad = good;
  bad[4] = 0;
  EXPECT_NE(Refusal(bad).find("unknown message type 0"), std::string::npos);
  bad[4] = 11;
  EXPECT_NE(Refusal(bad).find("unknown message type 11"), std::string::npos);
  bad = good;
  bad[3] = '1';  // the protocol's first version sent float64
  EXPECT_NE(Refusal(bad).find("another protocol version (magic PCN1"), std::string::npos);
  bad = good;
  bad[6] = 1;
  EXPECT_NE(Refusal(bad).find("reserved"), std::string::npos);
  // A frame one byte short or long, a patch count larger than the bytes, a huge count.
  EXPECT_NE(Refusal(good.substr(0, good.size() - 1)).find("need"), std::string::npos);
  EXPECT_NE(Refusal(good + "x").find("need"), std::string::npos);
  bad = good;
  const uint32_t more = 1000;
  std::memcpy(&bad[16], &more, 4);
  EXPECT_NE(Refusal(bad).find("1000 patches need"), std::string::npos);
  const uint32_t none = 0;  // found by the fuzz target (its memcpy of no bytes from null)
  std::memcpy(&bad[16], &none, 4);
  EXPECT_NE(Refusal(bad.substr(0, 24)).find("0 patches"), std::string::npos);
  const uint32_t huge = kMaxFramePatches + 1;
  std::memcpy(&bad[16], &huge, 4);
  EXPECT_NE(Refusal(bad).find("at most"), std::string::npos);
  // A value that is not finite (binary16 NaN and infinity), a scale out of range, a frame that
  // is not canonical (a channel's largest value not 1, or not 0 under a scale of 0).
  for (const uint16_t bits : {uint16_t{0x7e00}, uint16_t{0x7c00}}) {
    bad = good;
    std::memcpy(&bad[kFrameHeadBytes + 2 * 4], &bits, 2);
    EXPECT_NE(Refusal(bad).find("patch 1 channel 1 is not finite"), std::string::npos);
  }
  for (const double scale : {-1.0, 1e-31, 1e31, std::numeric_limits<double>::quiet_NaN()}) {
    bad = good;
    std::memcpy(&bad[24 + 8], &scale, 8);
    EXPECT_NE(Refusal(bad).find("channel 1's scale"), std::string::npos) << scale;
  }
  bad = good;
  const uint16_t half_quarter = 0x3400;
  std::memcpy(&bad[kFrameHeadBytes + 2 * 4], &half_quarter, 2);  // patch 1 held channel 1's 1
  EXPECT_NE(Refusal(bad).find("channel 1's largest value is"), std::string::npos);
  bad = good;
  const double zero = 0.0;
  std::memcpy(&bad[24 + 8], &zero, 8);
  EXPECT_NE(Refusal(bad).find("its scale is 0"), std::string::npos);
  // Payloads where none belongs, text that is not a JSON object, text too long.
  Message ping;
  ping.type = MessageType::kPing;
  EXPECT_NE(Refusal(EncodeMessage(ping) + "{}").find("no payload"), std::string::npos);
  Message ready;
  ready.type = MessageType::kReady;
  const std::string header = EncodeMessage(ready).substr(0, kMessageHeaderBytes);
  EXPECT_NE(Refusal(header + "{\"a\":").find("not JSON"), std::string::npos);
  EXPECT_NE(Refusal(header + "[1,2]").find("not a JSON object"), std::string::npos);
  EXPECT_NE(Refusal(header + "{\"a\":\"" + std::string(kMaxTextBytes, 'x') + "\"}").find("at most"),
            std::string::npos);
  Message presented;
  presented.type = MessageType::kPresented;
  EXPECT_NE(Refusal(EncodeMessage(presented).substr(0, 20)).find("no time"), std::string::npos);
}

TEST(NodeMessages, EncoderRefusesWhatTheParserWould) {
  Message frame;
  frame.type = MessageType::kFrame;
  frame.emittance = {1.0, 2.0};  // not n × 3
  EXPECT_THROW(EncodeMessage(frame), std::invalid_argument);
  Message ready;
  ready.type = MessageType::kReady;
  ready.body = nlohmann::json::array({1, 2});
  EXPECT_THROW(EncodeMessage(ready), std::invalid_argument);
  ready.body = {{"text", std::string(kMaxTextBytes, 'x')}};
  EXPECT_THROW(EncodeMessage(ready), std::invalid_argument);
}

// Random bytes and random mutations of good messages: the parser answers (true or false with a
// reason) and, when it accepts, re-encoding gives a message that parses to the same thing.
TEST(NodeMessages, RandomBytesNeverCrashTheParser) {
  std::mt19937 random(5);
  Message frame;
  frame.type = MessageType::kFrame;
  frame.emittance = {1.0, 2.0, 3.0};
  Message ready;
  ready.type = MessageType::kReady;
  ready.body = {{"node", "n"}};
  const std::string seeds[] = {EncodeMessage(frame), EncodeMessage(ready)};
  int accepted = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    std::string bytes = seeds[trial % 2];
    const int edits = 1 + static_cast<int>(random() % 4);
    for (int e = 0; e < edits; ++e) {
      const size_t at = random() % (bytes.size() + 1);
      switch (random() % 3) {
        case 0:
          if (at < bytes.size()) bytes[at] = static_cast<char>(random());
          break;
        case 1:
          bytes.insert(at, 1, static_cast<char>(random()));
          break;
        default:
          if (at < bytes.size()) bytes.erase(at, 1);
          break;
      }
    }
    Message message;
    std::string why;
    // A copy exactly as long as the message: AddressSanitizer sees any read past its end.
    std::vector<char> exact(bytes.begin(), bytes.end());
    if (ParseMessage(exact.data(), exact.size(), &message, &why)) {
      ++accepted;
      Message again;
      ASSERT_TRUE(
          ParseMessage(EncodeMessage(message).data(), EncodeMessage(message).size(), &again, &why))
          << why;
      EXPECT_EQ(again.type, message.type);
      EXPECT_EQ(again.emittance, message.emittance);
    } else {
      EXPECT_FALSE(why.empty());
    }
  }
  EXPECT_GT(accepted, 0);  // some mutations (e.g. of the sequence) stay messages
}

}  // namespace
}  // namespace procam
