// Uses an installed procam as a library: colour (CIEDE2000 against a published pair), .npy and
// .cameramodel files through the base module, a projector model, a display-node message. Exit 0
// when all agree.
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "base/camera_model.h"
#include "base/io.h"
#include "compensation/colour.h"
#include "nodes/messages.h"
#include "procam/config.h"
#include "projection/projector.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: consumer SCRATCH_DIR\n");
    return 2;
  }
  const std::filesystem::path dir = argv[1];
  int failures = 0;
  // Sharma, Wu & Dalal (2005), pair 1: ΔE00 = 2.0425.
  const double delta_e = procam::DeltaE2000({50.0, 2.6772, -79.7751}, {50.0, 0.0, -82.7485});
  if (std::abs(delta_e - 2.0425) > 1e-4) ++failures;

  procam::RowMatrixXd array(2, 3);
  array << 1, 2, 3, 4, 5, 6.5;
  procam::WriteNpy(dir / "a.npy", array);
  const procam::NpyArray back = procam::ReadNpy(dir / "a.npy");
  if (back.shape.size() != 2 || back.values[5] != 6.5) ++failures;

  const procam::ProjectorGeometry projector = procam::ProjectorGeometry::Pinhole(
      1000, 1000, 639.5, 399.5, 1280, 800, Eigen::Isometry3d::Identity());
  procam::WriteCameraModel(dir / "p.cameramodel", projector);
  const procam::CameraModel model = procam::ReadCameraModelFile(dir / "p.cameramodel");
  if (model.width != 1280 || model.intrinsics[0] != 1000.0) ++failures;

  procam::Message frame;
  frame.type = procam::MessageType::kFrame;
  frame.emittance = {0.25, 0.5, 0.75};
  const std::string bytes = procam::EncodeMessage(frame);
  procam::Message parsed;
  std::string why;
  if (!procam::ParseMessage(bytes.data(), bytes.size(), &parsed, &why) || parsed.emittance != frame.emittance) ++failures;

  std::printf("procam %s as a package: CIEDE2000 %.4f, .npy, .cameramodel and node message round trips: %s\n",
              PROCAM_VERSION, delta_e, failures == 0 ? "ok" : "FAILED");
  return failures == 0 ? 0 : 1;
}
