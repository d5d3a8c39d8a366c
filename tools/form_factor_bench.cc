// procam-form-factor-bench: the form factors of the benchmark room (closed box with an occluder,
// `procam bench formfactors` / `bench scale`'s room) against the number of threads, as a markdown
// table. A binary of its own, linked from the geometry sources with unused sections dropped, so
// that it needs only Embree, OpenCV's core and libgomp at run time and can be carried to a
// many-core machine without procam's other libraries (docs/scale.md).
//   procam-form-factor-bench [--sizes 10000,33333,100000] [--threads 1,2,4,8,16]
//                            [--dense-max-patches 10000]
#include <omp.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "datasets_synthetic/rooms.h"
#include "geometry/compressed_form_factors.h"
#include "geometry/form_factors.h"
#include "geometry/patches.h"

namespace {

std::vector<int> Integers(const char* flag, const std::string& text) {
  std::vector<int> values;
  std::stringstream stream(text);
  for (std::string item; std::getline(stream, item, ',');) {
    try {
      size_t used = 0;
      const int value = std::stoi(item, &used);
      if (used != item.size() || value < 1) throw std::invalid_argument(item);
      values.push_back(value);
    } catch (const std::exception&) {
      throw std::invalid_argument(std::string(flag) + ": '" + item + "' is not a positive integer");
    }
  }
  if (values.empty()) throw std::invalid_argument(std::string(flag) + ": empty list");
  return values;
}

int Run(int argc, char** argv) {
  std::vector<int> sizes = {10000, 33333, 100000};
  std::vector<int> threads = {1, 2, 4, 8, omp_get_num_procs()};
  int dense_max_patches = 10000;
  for (int k = 1; k < argc; ++k) {
    const std::string flag = argv[k];
    if (flag == "--help" || flag == "-h") {
      std::printf("usage: %s [--sizes N,...] [--threads T,...] [--dense-max-patches N]\n", argv[0]);
      return 0;
    }
    if (k + 1 >= argc) throw std::invalid_argument(flag + ": needs a value");
    const std::string value = argv[++k];
    if (flag == "--sizes") {
      sizes = Integers("--sizes", value);
    } else if (flag == "--threads") {
      threads = Integers("--threads", value);
    } else if (flag == "--dense-max-patches") {
      dense_max_patches = Integers("--dense-max-patches", value)[0];
    } else {
      throw std::invalid_argument("unknown option " + flag);
    }
  }
  std::printf("| patches | threads | compressed F s | near entries | far blocks | visibility rays | MB | dense F s |\n"
              "|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const int target : sizes) {
    const procam::SubdividedRoom room = procam::MakeSubdividedBoxRoom(target);
    const procam::Scene& scene = room.scene;
    const procam::PatchHierarchy& patches = room.patches;
    const int n = patches.fine.size();
    for (const int t : threads) {
      procam::FormFactorOptions options;
      options.threads = t;
      procam::CompressedBuildSummary build;
      procam::ComputeCompressedFormFactors(scene, patches.fine, options, procam::ClusterOptions(), &build);
      std::string dense = "–";
      if (n <= dense_max_patches) {
        procam::FormFactorSummary summary;
        procam::ComputeFormFactors(scene, patches.fine, options, &summary);
        char text[32];
        std::snprintf(text, sizeof text, "%.2f", summary.seconds);
        dense = text;
      }
      std::printf("| %d | %d | %.2f | %lld | %lld | %lld | %.0f | %s |\n", n, t, build.seconds,
                  static_cast<long long>(build.near_entries), static_cast<long long>(build.far_blocks),
                  static_cast<long long>(build.visibility_rays), build.bytes / 1e6, dense.c_str());
      std::fflush(stdout);
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const std::exception& error) {
    std::fprintf(stderr, "procam-form-factor-bench: error: %s\n", error.what());
    return 1;
  }
}
