// procam play's OSC address space (nodes/osc.h): datagrams written out byte by byte as OSC 1.0
// specifies them (addresses and type tags NUL-padded to 4 bytes, numbers big-endian) decode to
// the commands they name; everything else is refused with one line naming the address and why.
#include "nodes/osc.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

namespace procam {
namespace {

// OSC 1.0's encoding, written here apart from liblo's.
std::vector<uint8_t> Padded(const std::string& text) {
  std::vector<uint8_t> bytes(text.begin(), text.end());
  bytes.push_back(0);
  while (bytes.size() % 4 != 0) bytes.push_back(0);
  return bytes;
}
void Append(std::vector<uint8_t>* bytes, const std::vector<uint8_t>& more) {
  bytes->insert(bytes->end(), more.begin(), more.end());
}
std::vector<uint8_t> BigEndian(uint32_t word) {
  return {uint8_t(word >> 24), uint8_t(word >> 16), uint8_t(word >> 8), uint8_t(word)};
}
std::vector<uint8_t> Float(float value) {
  uint32_t word;
  std::memcpy(&word, &value, 4);
  return BigEndian(word);
}
std::vector<uint8_t> Int(int32_t value) { return BigEndian(static_cast<uint32_t>(value)); }

std::vector<uint8_t> Datagram(const std::string& address, const std::string& types,
                              const std::vector<std::vector<uint8_t>>& arguments) {
  std::vector<uint8_t> bytes = Padded(address);
  Append(&bytes, Padded("," + types));
  for (const auto& argument : arguments) Append(&bytes, argument);
  return bytes;
}

// Decodes and parses; on refusal returns false with `*why`.
bool Command(const std::vector<uint8_t>& bytes, OscCommand* command, std::string* why) {
  OscMessage message;
  return DecodeOscPacket(bytes.data(), bytes.size(), &message, why) &&
         ParseOscCommand(message, command, why);
}

TEST(Osc, DatagramsDecodeToTheCommandsTheyName) {
  OscCommand command;
  std::string why;
  ASSERT_TRUE(Command(Datagram("/procam/pause", "", {}), &command, &why)) << why;
  EXPECT_EQ(command.kind, OscCommand::Kind::kPause);
  ASSERT_TRUE(Command(Datagram("/procam/fade", "ff", {Float(0.25f), Float(1.5f)}), &command, &why))
      << why;
  EXPECT_EQ(command.kind, OscCommand::Kind::kFade);
  EXPECT_EQ(command.level, 0.25);
  EXPECT_EQ(command.seconds, 1.5);
  EXPECT_EQ(command.Text(), "fade 0.25 1.5");
  // An integer level (a desk sends 0 or 1) and no duration: at once.
  ASSERT_TRUE(Command(Datagram("/procam/fade", "i", {Int(0)}), &command, &why)) << why;
  EXPECT_EQ(command.level, 0.0);
  EXPECT_EQ(command.seconds, 0.0);
  ASSERT_TRUE(Command(Datagram("/procam/seek", "i", {Int(12)}), &command, &why)) << why;
  EXPECT_EQ(command.kind, OscCommand::Kind::kSeek);
  EXPECT_EQ(command.seconds, 12.0);
  ASSERT_TRUE(Command(Datagram("/procam/method", "s", {Padded("linear")}), &command, &why)) << why;
  EXPECT_EQ(command.method, "linear");
  ASSERT_TRUE(Command(Datagram("/procam/tolerance", "f", {Float(0.01f)}), &command, &why)) << why;
  EXPECT_NEAR(command.tolerance, 0.01, 1e-9);
  ASSERT_TRUE(
      Command(Datagram("/procam/surface/back_wall", "s", {Padded("clouds")}), &command, &why))
      << why;
  EXPECT_EQ(command.surface, "back_wall");
  EXPECT_EQ(command.content, "clouds");
  ASSERT_TRUE(Command(Datagram("/procam/surface/floor", "s", {Padded("none")}), &command, &why));
  EXPECT_EQ(command.content, "");
  ASSERT_TRUE(Command(Datagram("/procam/surface", "ss", {Padded("back wall"), Padded("rain")}),
                      &command, &why))
      << why;
  EXPECT_EQ(command.surface, "back wall");
  EXPECT_EQ(command.content, "rain");
  for (const char* name : {"play", "status", "stop"})
    EXPECT_TRUE(Command(Datagram(std::string("/procam/") + name, "", {}), &command, &why)) << why;
}

TEST(Osc, MalformedMessagesAreRefusedInOneLineNamingAddressAndArgument) {
  const float nan = std::nanf("");
  const struct {
    std::vector<uint8_t> bytes;
    std::string why;
  } cases[] = {
      {Datagram("/procam/fade", "f", {Float(2.0f)}),
       "/procam/fade: argument 1 (level) must be in [0, 1], got 2"},
      {Datagram("/procam/fade", "f", {Float(nan)}), "/procam/fade: argument 1 (level) must be in"},
      {Datagram("/procam/fade", "ff", {Float(1.0f), Float(-1.0f)}),
       "/procam/fade: argument 2 (seconds) must be in [0, 3600], got -1"},
      {Datagram("/procam/fade", "s", {Padded("black")}),
       "/procam/fade: argument 1 (level) must be a number"},
      {Datagram("/procam/fade", "", {}), "/procam/fade: takes 1 to 2 arguments, got 0"},
      {Datagram("/procam/pause", "i", {Int(1)}), "/procam/pause: takes 0 argument(s), got 1"},
      {Datagram("/procam/method", "s", {Padded("magic")}),
       "/procam/method: argument 1 (method) must be naive, reverse"},
      {Datagram("/procam/tolerance", "f", {Float(0.5f)}),
       "/procam/tolerance: argument 1 (tolerance) must be in [0, 0.1], got 0.5"},
      {Datagram("/procam/surface/a/b", "s", {Padded("x")}),
       "/procam/surface/a/b: the surface's name holds '/'"},
      {Datagram("/procam/surface/", "s", {Padded("x")}),
       "/procam/surface/: the surface's name is empty"},
      {Datagram("/procam/rewind", "", {}), "/procam/rewind: no such address"},
      {Datagram("/procam/surface", "s", {Padded("floor")}),
       "/procam/surface: takes 2 argument(s), got 1"},
      {Datagram("/lights/go", "", {}), "/lights/go: not an address of procam's"},
      // A byte that would break the log's line is written as its code.
      {Datagram("/procam\nstatus", "", {}), "/procam\\x0astatus: not an address of procam's"},
      {Padded("#bundle"), "an OSC bundle"},
      {{}, "an empty datagram"},
      {{'x', 0, 0, 0}, "not an OSC message"},
  };
  for (const auto& c : cases) {
    OscCommand command;
    std::string why;
    EXPECT_FALSE(Command(c.bytes, &command, &why)) << c.why;
    EXPECT_NE(why.find(c.why), std::string::npos)
        << "expected '" << c.why << "', got '" << why << "'";
    EXPECT_EQ(why.find('\n'), std::string::npos) << why;
  }
  // A datagram cut short: its last argument's bytes missing.
  std::vector<uint8_t> cut = Datagram("/procam/fade", "ff", {Float(1.0f), Float(1.0f)});
  cut.resize(cut.size() - 4);
  OscCommand command;
  std::string why;
  EXPECT_FALSE(Command(cut, &command, &why));
  EXPECT_NE(why.find("not an OSC message"), std::string::npos) << why;
}

TEST(Osc, EncodedMessagesAreTheBytesOsc10Specifies) {
  OscMessage message;
  message.address = "/procam/status";
  message.types = "ifs";
  message.arguments = {{'i', 7, ""}, {'f', 29.5, ""}, {'s', 0, "ok"}};
  EXPECT_EQ(EncodeOscMessage(message),
            Datagram("/procam/status", "ifs", {Int(7), Float(29.5f), Padded("ok")}));
}

TEST(Osc, TheAllowListMatchesAddressesAndRanges) {
  uint32_t address = 0;
  ASSERT_TRUE(ParseIpv4("192.168.1.20", &address));
  EXPECT_EQ(address, (192u << 24) | (168u << 16) | (1u << 8) | 20u);
  EXPECT_EQ(Ipv4Text(address), "192.168.1.20");
  for (const char* bad : {"192.168.1", "192.168.1.256", "a.b.c.d", "1.2.3.4.5", "", "1..2.3"})
    EXPECT_FALSE(ParseIpv4(bad, &address)) << bad;
  const OscAllowList list = OscAllowList::Parse({"127.0.0.1", "10.1.0.0/16"});
  uint32_t loopback, other_loopback, inside, outside;
  ParseIpv4("127.0.0.1", &loopback);
  ParseIpv4("127.0.0.2", &other_loopback);
  ParseIpv4("10.1.200.3", &inside);
  ParseIpv4("10.2.0.1", &outside);
  EXPECT_TRUE(list.Allows(loopback));
  EXPECT_FALSE(list.Allows(other_loopback));
  EXPECT_TRUE(list.Allows(inside));
  EXPECT_FALSE(list.Allows(outside));
  EXPECT_TRUE(OscAllowList::Parse({"0.0.0.0/0"}).Allows(outside));
  EXPECT_FALSE(OscAllowList().Allows(loopback));
  for (const char* bad : {"10.0.0.0/33", "10.0.0.0/", "localhost", "10.0.0.0/8x"}) {
    try {
      OscAllowList::Parse({bad});
      ADD_FAILURE() << bad << " was taken";
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find(std::string("--osc-allow: '") + bad + "'"),
                std::string::npos)
          << error.what();
    }
  }
}

}  // namespace
}  // namespace procam
