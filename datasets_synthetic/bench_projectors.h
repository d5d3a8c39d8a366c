#pragma once
// The projectors of procam's benchmarks on the box room (rooms.h): `count` of them (2 or 3),
// `width` × `height` pixels, near the front wall, overlapping on the back wall and the occluder.

#include <vector>

#include "projection/projector.h"

namespace procam {

std::vector<Projector> BoxRoomProjectors(int count, int width, int height);

}  // namespace procam
