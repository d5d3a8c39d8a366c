#pragma once
// A show's playlist (`procam play --playlist FILE`, docs/show.md#a-playlist): content made per
// surface of the room, in the surface's own texture coordinates (the scene's `desired` textures,
// docs/scene_format.md), which moves: a video, an image sequence or one image per surface, each
// from a start time of the show. The playlist file has one owner (this header): ReadPlaylist and
// WritePlaylist, format version 1:
//
//   {"format_version": 1,
//    "contents": {"clouds": {"video": "clouds.mp4", "loop": true},
//                 "poster": {"image": "poster.png"},
//                 "flipbook": {"images": "flipbook/"}},
//    "surfaces": [{"surface": "back wall", "content": "clouds", "start": 0.0}]}
//
// Paths are relative to the playlist file. A content's frame k is shown at its start + k / fps
// (the show's --fps); at its end it holds its last frame, or starts again with "loop": true.
// `/procam/surface/NAME CONTENT` (nodes/osc.h) switches a surface's content from the frame it
// applies at.

#include <filesystem>
#include <string>
#include <vector>

namespace procam {

struct PlaylistContent {
  enum class Kind { kVideo, kImages, kImage };
  std::string name;
  Kind kind = Kind::kVideo;
  std::string path;                // as written (relative to the playlist file)
  std::filesystem::path resolved;  // the file or directory it names (set by ReadPlaylist)
  bool loop = false;               // start again at the end (else hold the last frame)
};

struct PlaylistEntry {
  std::string surface;  // a surface's name in the scene
  std::string content;  // a content's name
  double start = 0.0;   // seconds from the show's first frame, >= 0
};

struct Playlist {
  static constexpr int kFormatVersion = 1;
  std::vector<PlaylistContent> contents;
  std::vector<PlaylistEntry> surfaces;
  // The content named `name`, or nullptr.
  const PlaylistContent* Find(const std::string& name) const;
};

// Reads and checks a playlist. Throws IoError as "FILE: KEY: what" (surfaces[1].content: no
// content 'x' in "contents"; contents.clouds.video: no such file), naming the file and key.
Playlist ReadPlaylist(const std::filesystem::path& path);

// Writes `playlist` (paths as written), atomically.
void WritePlaylist(const std::filesystem::path& path, const Playlist& playlist);

}  // namespace procam
