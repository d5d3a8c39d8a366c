#pragma once
// procam compensate as one call: the room calibrated by a rig (or a scene file's own
// projectors), solved for the desired appearance within what its projectors emit, and the
// solution written. The command and the demo's compensation stage both run it.

#include "compensation/stage.h"
#include "projection/calibrated_room.h"

namespace procam {

// Checks `output.out` (a new directory or an earlier solution, never another kind's), reads the
// room's sources (a bad rig.json fails before any form factor), builds the room (its `problem`
// is not made: RunCompensation makes the fine and coarse problems), bounds the solve by the
// projectors' light (a room without projectors is solved within the scene's "bounds", with one
// warning through `room.progress` saying so, as procam project then needs a rig), solves and writes
// the solution with the rig's description. Throws std::invalid_argument / std::runtime_error with
// one line naming what is wrong (a --device cuda without a device before anything is read; --export
// with compressed form factors).
CompensationRun CompensateRoom(CalibratedRoomOptions room, const CompensationOptions& options,
                               const SolutionOutputOptions& output);

}  // namespace procam
