// The playlist file (nodes/playlist.h): what WritePlaylist writes ReadPlaylist reads back the
// same, and every mistake is one error naming the file and the key.
#include "nodes/playlist.h"

#include <gtest/gtest.h>

#include "base/io.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

TEST(Playlist, WhatIsWrittenReadsBackTheSame) {
  testing::TempDir dir;
  WriteFileAtomically(dir / "clouds.avi", "not read here");
  WriteFileAtomically(dir / "poster.png", "not read here");
  std::filesystem::create_directories(dir / "flipbook");
  Playlist playlist;
  playlist.contents = {{"clouds", PlaylistContent::Kind::kVideo, "clouds.avi", {}, true},
                       {"poster", PlaylistContent::Kind::kImage, "poster.png", {}, false},
                       {"flipbook", PlaylistContent::Kind::kImages, "flipbook", {}, false}};
  playlist.surfaces = {
      {"back wall", "clouds", 0.0}, {"floor", "poster", 2.5}, {"back wall", "flipbook", 10.0}};
  WritePlaylist(dir / "show.json", playlist);
  const Playlist read = ReadPlaylist(dir / "show.json");
  ASSERT_EQ(read.contents.size(), 3u);
  for (const PlaylistContent& content : playlist.contents) {
    const PlaylistContent* found = read.Find(content.name);
    ASSERT_NE(found, nullptr) << content.name;
    EXPECT_EQ(found->kind, content.kind);
    EXPECT_EQ(found->path, content.path);
    EXPECT_EQ(found->loop, content.loop);
    EXPECT_EQ(found->resolved, dir / content.path);
  }
  ASSERT_EQ(read.surfaces.size(), 3u);
  for (size_t k = 0; k < 3; ++k) {
    EXPECT_EQ(read.surfaces[k].surface, playlist.surfaces[k].surface);
    EXPECT_EQ(read.surfaces[k].content, playlist.surfaces[k].content);
    EXPECT_EQ(read.surfaces[k].start, playlist.surfaces[k].start);
  }
}

TEST(Playlist, MistakesNameTheFileAndTheKey) {
  testing::TempDir dir;
  WriteFileAtomically(dir / "clouds.avi", "not read here");
  const std::string file = (dir / "show.json").string();
  const struct {
    std::string json, expected;
  } cases[] = {
      {R"({"format_version": 2, "contents": {}, "surfaces": []})",
       file + ": format_version: this procam reads version 1"},
      {R"({"format_version": 1, "contents": {"c": {"video": "gone.avi"}}, "surfaces": []})",
       file + ": contents.c.video: " + (dir / "gone.avi").string() + ": no such file"},
      {R"({"format_version": 1, "contents": {"c": {"video": "clouds.avi", "image": "clouds.avi"}},
          "surfaces": []})",
       file + ": contents.c: give one of video, images"},
      {R"({"format_version": 1, "contents": {"c": {"video": "clouds.avi"}},
          "surfaces": [{"surface": "floor", "content": "rain"}]})",
       file + ": surfaces[0].content: no content 'rain' in \"contents\""},
      {R"({"format_version": 1, "contents": {"c": {"video": "clouds.avi"}},
          "surfaces": [{"surface": "floor", "content": "c", "start": -1}]})",
       file + ": surfaces[0].start: must be in [0, 1e7] seconds"},
      {R"({"format_version": 1, "contents": {"c": {"video": "clouds.avi", "loop": 1}},
          "surfaces": []})",
       file + ": contents.c.loop: must be true or false"},
      {R"({"format_version": 1, "contents": {}, "surfaces": [], "cues": []})",
       file + ": cues: unknown key"},
  };
  for (const auto& c : cases) {
    WriteFileAtomically(dir / "show.json", c.json);
    try {
      ReadPlaylist(dir / "show.json");
      ADD_FAILURE() << "read: " << c.json;
    } catch (const IoError& error) {
      EXPECT_EQ(std::string(error.what()).rfind(c.expected, 0), 0u)
          << "expected '" << c.expected << "', got '" << error.what() << "'";
    }
  }
}

}  // namespace
}  // namespace procam
