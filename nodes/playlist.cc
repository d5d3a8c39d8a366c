#include "nodes/playlist.h"

#include <nlohmann/json.hpp>

#include "base/io.h"
#include "base/json_fields.h"

namespace procam {

const PlaylistContent* Playlist::Find(const std::string& name) const {
  for (const PlaylistContent& content : contents)
    if (content.name == name) return &content;
  return nullptr;
}

Playlist ReadPlaylist(const std::filesystem::path& path) {
  const nlohmann::json document = ReadJsonFile(path);
  const std::string file = path.string();
  if (!document.is_object()) throw IoError(file + ": a playlist is a JSON object");
  const JsonFields top(document, file, "");
  top.RejectUnknown({"format_version", "contents", "surfaces"});
  const double version = top.Number("format_version");
  if (version != Playlist::kFormatVersion)
    throw top.Error("format_version",
                    "this procam reads version " + std::to_string(Playlist::kFormatVersion));
  const std::filesystem::path base = path.parent_path();
  Playlist playlist;
  const nlohmann::json& contents = top.At("contents");
  if (!contents.is_object()) throw top.Error("contents", "must be an object of named contents");
  for (const auto& item : contents.items()) {
    if (!item.value().is_object())
      throw top.Error("contents." + item.key(), "must be an object ({\"video\": FILE}, ...)");
    const JsonFields fields(item.value(), file, "contents." + item.key());
    fields.RejectUnknown({"video", "images", "image", "loop"});
    PlaylistContent content;
    content.name = item.key();
    int kinds = 0;
    for (const auto& [key, kind] : {std::pair{"video", PlaylistContent::Kind::kVideo},
                                    std::pair{"images", PlaylistContent::Kind::kImages},
                                    std::pair{"image", PlaylistContent::Kind::kImage}}) {
      if (!fields.Has(key)) continue;
      ++kinds;
      content.kind = kind;
      content.path = fields.String(key);
      content.resolved = base / content.path;
      const bool directory = kind == PlaylistContent::Kind::kImages;
      if (directory ? !std::filesystem::is_directory(content.resolved)
                    : !std::filesystem::is_regular_file(content.resolved))
        throw fields.Error(
            key, content.resolved.string() + ": no such " + (directory ? "directory" : "file"));
    }
    if (kinds != 1) throw fields.Error("", "give one of video, images (a directory) or image");
    if (fields.Has("loop")) {
      if (!fields.At("loop").is_boolean()) throw fields.Error("loop", "must be true or false");
      content.loop = fields.At("loop").get<bool>();
    }
    playlist.contents.push_back(content);
  }
  const nlohmann::json& surfaces = top.At("surfaces");
  if (!surfaces.is_array()) throw top.Error("surfaces", "must be an array");
  for (size_t k = 0; k < surfaces.size(); ++k) {
    const std::string prefix = "surfaces[" + std::to_string(k) + "]";
    if (!surfaces[k].is_object()) throw top.Error(prefix, "must be an object");
    const JsonFields fields(surfaces[k], file, prefix);
    fields.RejectUnknown({"surface", "content", "start"});
    PlaylistEntry entry;
    entry.surface = fields.String("surface");
    entry.content = fields.String("content");
    if (playlist.Find(entry.content) == nullptr)
      throw fields.Error("content", "no content '" + entry.content + "' in \"contents\"");
    if (fields.Has("start")) {
      entry.start = fields.Number("start");
      if (!(entry.start >= 0.0 && entry.start <= 1e7))
        throw fields.Error("start", "must be in [0, 1e7] seconds");
    }
    for (const PlaylistEntry& earlier : playlist.surfaces)
      if (earlier.surface == entry.surface && earlier.start == entry.start)
        throw fields.Error("surface", "'" + entry.surface + "' has two contents at " +
                                          std::to_string(entry.start) + " s");
    playlist.surfaces.push_back(entry);
  }
  return playlist;
}

void WritePlaylist(const std::filesystem::path& path, const Playlist& playlist) {
  nlohmann::json document = {{"format_version", Playlist::kFormatVersion},
                             {"contents", nlohmann::json::object()},
                             {"surfaces", nlohmann::json::array()}};
  for (const PlaylistContent& content : playlist.contents) {
    const char* key = content.kind == PlaylistContent::Kind::kVideo    ? "video"
                      : content.kind == PlaylistContent::Kind::kImages ? "images"
                                                                       : "image";
    document["contents"][content.name] = {{key, content.path}, {"loop", content.loop}};
  }
  for (const PlaylistEntry& entry : playlist.surfaces)
    document["surfaces"].push_back(
        {{"surface", entry.surface}, {"content", entry.content}, {"start", entry.start}});
  WriteFileAtomically(path, document.dump(2) + "\n");
}

}  // namespace procam
