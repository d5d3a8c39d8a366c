// LoadObjMesh (geometry/obj_mesh.cc): the strict reader of OBJ v, vt, vn and f lines.
#include "fuzz/fuzz_input.h"
#include "geometry/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = procam::WriteFuzzInput(data, size, "input.obj");
  procam::ReadOrRefuse([&] {
    procam::Surface surface;
    procam::LoadObjMesh(path, 1e-6, &surface);
  });
  return 0;
}
