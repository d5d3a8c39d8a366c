#pragma once
// Rooms made at random from a seed: what the scan is judged on besides the built-in scenes
// (docs/synthetic.md#rooms-made-at-random). A floor plan of 4–7 walls meeting at angles other
// than 90° (the front, where the audience stands, open), recesses and alcoves in the walls,
// free-standing boxes, plinths, round and polygonal columns, slanted panels and steps, an
// optional ceiling; two or three projectors and a camera placed so that most of the room is lit
// and seen; reflectances and desired colours drawn at random.
//
// The room depends on the seed alone, identically on every platform: the numbers come from a
// std::mt19937_64 (whose sequence the C++ standard fixes) turned into doubles by explicit
// arithmetic, never through the standard distributions (whose algorithms it leaves open).

#include <cstdint>
#include <filesystem>
#include <string>

#include "base/option_table.h"
#include "datasets_synthetic/paper_scenes.h"

namespace procam {

struct RandomRoomOptions {
  uint64_t seed = 1;  // any value; the same seed gives the same room
  int patches = 600;  // the scene's patch target, ≥ 1
  // Placements of the projectors and the camera drawn; the one under which the largest share of
  // the room's area is seen by the camera and lit by a projector is kept, ≥ 1.
  int placement_candidates = 6;
  // Declares --seed and --patches in `table`, bound to these fields (base/option_table.h).
  void Declare(OptionTable* table);
  bool Check(std::string* why) const;
};

// Declares a 64-bit seed `name` (a whole number) in `table`, bound to `*seed`.
OptionTable& DeclareSeedOption(OptionTable* table, const std::string& name, uint64_t* seed,
                               const std::string& help);

struct RandomRoom {
  SyntheticScene synthetic;  // surfaces (named after what they are), projector and camera placements
  std::string name;          // "random_SEED"
  std::string description;   // one line: walls, recesses, objects, ceiling, projectors
  // The share of the room's area the camera sees and a projector lights (SeenAndLitArea at 5 cm
  // cells), in [0, 1]: of every surface but the ceiling, which projectors hung under it do not
  // light.
  double coverage = 0.0;
  int walls = 0;  // walls of the floor plan (not counting the sides of recesses)
};

// The room of `options.seed`. Throws std::invalid_argument when the options fail Check().
RandomRoom MakeRandomRoom(const RandomRoomOptions& options);

// Writes the room as a scene file with its projectors and camera into `dir` (random_SEED.json,
// a .cameramodel per device, an OBJ per mesh surface) through WriteSyntheticSceneFile; returns
// the scene file's path. Throws like it.
std::filesystem::path WriteRandomRoom(const RandomRoomOptions& options,
                                      const std::filesystem::path& dir);

}  // namespace procam
