#include "calibration/mrcal_chessboard.h"

#include <fmt/format.h>

#include <array>
#include <cstdint>
#include <cstring>
#include <stdexcept>

#include "base/camera_model.h"

#include <suitesparse/cholmod.h>  // the cholmod_sparse that carries Jᵀ (the struct only)

extern "C" {
// _mrcal_num_j_nonzero: the Jacobian's size, which mrcal's Python wrapper asks for the same way.
#include <mrcal/mrcal-internal.h>
}

namespace procam {

mrcal_problem_selections_t ChessboardSelections(bool regularization, bool reject_outliers) {
  mrcal_problem_selections_t selections{};
  selections.do_optimize_intrinsics_core = true;
  selections.do_optimize_intrinsics_distortions = true;
  selections.do_optimize_extrinsics = true;
  selections.do_optimize_frames = true;
  selections.do_optimize_calobject_warp = false;
  selections.do_apply_regularization = regularization;
  selections.do_apply_outlier_rejection = reject_outliers;
  return selections;
}

MrcalChessboardProblem ToMrcal(const CameraCalibration& calibration) {
  const ChessboardSolve& solve = calibration.solve;
  const int views = static_cast<int>(calibration.cam_from_board.size());
  if (views == 0 ||
      solve.corners.size() != static_cast<size_t>(views) * solve.board.CornerCount()) {
    throw std::invalid_argument("camera calibration: no chessboard solve to evaluate (" +
                                std::to_string(solve.corners.size()) + " corners for " +
                                std::to_string(views) + " views)");
  }
  MrcalChessboardProblem problem;
  if (!mrcal_lensmodel_from_name(&problem.lens, calibration.lens_model.c_str())) {
    throw std::invalid_argument("unknown mrcal lens model '" + calibration.lens_model + "'");
  }
  problem.intrinsics = calibration.intrinsics;
  problem.frames.resize(views);
  problem.observations.resize(views);
  for (int v = 0; v < views; ++v) {
    const std::array<double, 6> rt = RtFromPose(calibration.cam_from_board[v]);
    std::memcpy(&problem.frames[v], rt.data(), sizeof(rt));
    problem.observations[v].icam.intrinsics = 0;
    problem.observations[v].icam.extrinsics = -1;  // the camera is the reference frame
    problem.observations[v].iframe = v;
  }
  problem.pool.resize(solve.corners.size());
  for (size_t k = 0; k < solve.corners.size(); ++k) {
    problem.pool[k] =
        mrcal_point3_t{{solve.corners[k].x(), solve.corners[k].y(), solve.corners[k].z()}};
  }
  problem.selections = ChessboardSelections(solve.regularization, solve.reject_outliers);
  problem.imager_sizes = {calibration.width, calibration.height};
  problem.spacing = solve.board.square_size;
  problem.corners_x = solve.board.corners_x;
  problem.corners_y = solve.board.corners_y;
  return problem;
}

int MrcalChessboardProblem::StateCount() const {
  return mrcal_num_states(cameras, Extrinsics(), Frames(), 0, 0, Observations(), selections, &lens);
}

int MrcalChessboardProblem::MeasurementCount() const {
  return mrcal_num_measurements(Observations(), 0, corners_x, corners_y, cameras, Extrinsics(),
                                Frames(), 0, 0, selections, &lens);
}

int MrcalChessboardProblem::BoardMeasurementCount() const {
  return mrcal_num_measurements_boards(Observations(), corners_x, corners_y);
}

int MrcalChessboardProblem::StateIndexIntrinsics() const { return StateIndexIntrinsics(0); }

int MrcalChessboardProblem::StateIndexIntrinsics(int camera) const {
  return mrcal_state_index_intrinsics(camera, cameras, Extrinsics(), Frames(), 0, 0,
                                      Observations(), selections, &lens);
}

int MrcalChessboardProblem::StateIndexExtrinsics(int camera) const {
  return mrcal_state_index_extrinsics(camera - 1, cameras, Extrinsics(), Frames(), 0, 0,
                                      Observations(), selections, &lens);
}

int MrcalChessboardProblem::StateIndexFrames() const {
  return mrcal_state_index_frames(0, cameras, Extrinsics(), Frames(), 0, 0, Observations(),
                                  selections, &lens);
}

int MrcalChessboardProblem::JacobianNonZeros() const {
  return _mrcal_num_j_nonzero(Observations(), 0, corners_x, corners_y, cameras, Extrinsics(),
                              Frames(), 0, 0, observations.data(), nullptr, selections, &lens);
}

bool MrcalChessboardProblem::Evaluate(std::vector<double>* x, std::vector<int>* column_starts,
                                      std::vector<int>* rows, std::vector<double>* values) const {
  const int state_count = StateCount();
  const int measurement_count = MeasurementCount();
  const int nonzeros = JacobianNonZeros();
  std::vector<double> b_packed(state_count);
  x->assign(measurement_count, 0.0);
  values->assign(nonzeros, 0.0);
  column_starts->assign(measurement_count + 1, 0);
  rows->assign(nonzeros, 0);
  cholmod_sparse jt{};
  jt.nrow = state_count;
  jt.ncol = measurement_count;
  jt.nzmax = nonzeros;
  jt.p = column_starts->data();
  jt.i = rows->data();
  jt.x = values->data();
  jt.stype = 0;
  jt.itype = CHOLMOD_INT;
  jt.xtype = CHOLMOD_REAL;
  jt.dtype = CHOLMOD_DOUBLE;
  jt.sorted = 1;
  jt.packed = 1;
  // libmrcal takes non-const arrays but only reads them here.
  MrcalChessboardProblem& self = const_cast<MrcalChessboardProblem&>(*this);
  return mrcal_optimizer_callback(
      b_packed.data(), state_count * sizeof(double), x->data(), measurement_count * sizeof(double),
      &jt, self.intrinsics.data(), self.extrinsics.empty() ? nullptr : self.extrinsics.data(),
      self.frames.data(), nullptr, nullptr, cameras, Extrinsics(), Frames(), 0, 0,
      observations.data(), nullptr, Observations(), 0, self.pool.data(), &lens,
      imager_sizes.data(), selections, &kChessboardConstants, spacing, corners_x, corners_y,
      false);
}

namespace {

// One .npy file (format 1.0): `descr` is NumPy's dtype string, `shape` a Python tuple ("()" for a
// scalar), `data` the little-endian values in C order.
std::string Npy(const std::string& descr, const std::string& shape, const std::string& data) {
  std::string dict =
      fmt::format("{{'descr': '{}', 'fortran_order': False, 'shape': {}, }}", descr, shape);
  // NumPy pads the header with spaces and a newline so that the data starts 64-byte aligned.
  const size_t unpadded = 10 + dict.size() + 1;
  dict.append((unpadded + 63) / 64 * 64 - unpadded, ' ');
  dict.push_back('\n');
  std::string bytes("\x93NUMPY\x01\x00", 8);
  bytes.push_back(static_cast<char>(dict.size() & 0xff));
  bytes.push_back(static_cast<char>(dict.size() >> 8));
  return bytes + dict + data;
}

template <typename T>
std::string Raw(const T* values, size_t count) {
  return std::string(reinterpret_cast<const char*>(values), sizeof(T) * count);
}

std::string NpyDoubles(const std::vector<double>& values, const std::string& shape) {
  return Npy("<f8", shape, Raw(values.data(), values.size()));
}
std::string NpyInts(const std::vector<int32_t>& values, const std::string& shape) {
  return Npy("<i4", shape, Raw(values.data(), values.size()));
}
std::string NpyBool(bool value) { return Npy("|b1", "()", std::string(1, value ? 1 : 0)); }
std::string NpyDouble(double value) { return Npy("<f8", "()", Raw(&value, 1)); }
std::string NpyInt64(int64_t value) { return Npy("<i8", "()", Raw(&value, 1)); }
// A Python str (NumPy's '<U', UCS-4); the empty one stands for None.
std::string NpyString(const std::string& ascii) {
  std::vector<uint32_t> code_points(ascii.begin(), ascii.end());
  return Npy(fmt::format("<U{}", std::max<size_t>(ascii.size(), 1)), "()",
             ascii.empty() ? std::string(4, '\0') : Raw(code_points.data(), code_points.size()));
}

uint32_t Crc32(const std::string& bytes) {
  uint32_t crc = 0xffffffffu;
  for (unsigned char byte : bytes) {
    crc ^= byte;
    for (int bit = 0; bit < 8; ++bit) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

void Put16(std::string* out, uint32_t value) {
  out->push_back(static_cast<char>(value & 0xff));
  out->push_back(static_cast<char>((value >> 8) & 0xff));
}
void Put32(std::string* out, uint32_t value) {
  Put16(out, value & 0xffff);
  Put16(out, value >> 16);
}

// A zip archive of stored (uncompressed) members, as np.load reads an .npz (PKWARE APPNOTE 4.3:
// local headers and data, the central directory, its end record). Dates are 1980-01-01.
std::string Zip(const std::vector<std::pair<std::string, std::string>>& members) {
  std::string archive, directory;
  for (const auto& member : members) {
    // Plain references, not structured bindings: clang 14 (the fuzz build) cannot capture those.
    const std::string& name = member.first;
    const std::string& data = member.second;
    const uint32_t crc = Crc32(data);
    const uint32_t offset = static_cast<uint32_t>(archive.size());
    auto common = [&](std::string* out) {
      Put16(out, 20);    // version needed: 2.0
      Put16(out, 0);     // flags
      Put16(out, 0);     // method: stored
      Put16(out, 0);     // time
      Put16(out, 0x21);  // date: 1980-01-01
      Put32(out, crc);
      Put32(out, static_cast<uint32_t>(data.size()));  // compressed size
      Put32(out, static_cast<uint32_t>(data.size()));  // uncompressed size
      Put16(out, static_cast<uint32_t>(name.size()));
      Put16(out, 0);  // extra field length
    };
    Put32(&archive, 0x04034b50);
    common(&archive);
    archive += name + data;
    Put32(&directory, 0x02014b50);
    Put16(&directory, 20);  // version made by
    common(&directory);
    Put16(&directory, 0);  // comment length
    Put16(&directory, 0);  // disk number
    Put16(&directory, 0);  // internal attributes
    Put32(&directory, 0);  // external attributes
    Put32(&directory, offset);
    directory += name;
  }
  const uint32_t directory_offset = static_cast<uint32_t>(archive.size());
  archive += directory;
  Put32(&archive, 0x06054b50);
  Put16(&archive, 0);
  Put16(&archive, 0);
  Put16(&archive, static_cast<uint32_t>(members.size()));
  Put16(&archive, static_cast<uint32_t>(members.size()));
  Put32(&archive, static_cast<uint32_t>(directory.size()));
  Put32(&archive, directory_offset);
  Put16(&archive, 0);  // comment length
  return archive;
}

// Python's base64.b85encode: each 4 bytes (big-endian) as 5 base-85 digits, most significant
// first; a last partial group is padded with zeros and its padding's digits dropped.
std::string Base85(const std::string& bytes) {
  static const char kDigits[] =
      "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz!#$%&()*+-;<=>?@^_`{|}~";
  std::string text;
  text.reserve(bytes.size() / 4 * 5 + 5);
  for (size_t start = 0; start < bytes.size(); start += 4) {
    const size_t count = std::min<size_t>(4, bytes.size() - start);
    uint32_t word = 0;
    for (size_t k = 0; k < 4; ++k) {
      word = (word << 8) | (k < count ? static_cast<unsigned char>(bytes[start + k]) : 0u);
    }
    char digits[5];
    for (int k = 4; k >= 0; --k) {
      digits[k] = kDigits[word % 85];
      word /= 85;
    }
    text.append(digits, count + 1);
  }
  return text;
}

}  // namespace

std::string MrcalOptimizationInputs(const CameraCalibration& calibration) {
  return MrcalOptimizationInputs(ToMrcal(calibration), calibration.lens_model);
}

std::string MrcalOptimizationInputs(const MrcalChessboardProblem& problem,
                                    const std::string& lens_model) {
  const int views = problem.Frames();
  const int observation_count = problem.Observations();
  const int per_camera = static_cast<int>(problem.intrinsics.size()) / problem.cameras;
  std::vector<double> frames(6 * views), pool(3 * problem.pool.size());
  std::vector<double> extrinsics(6 * problem.Extrinsics());
  std::memcpy(frames.data(), problem.frames.data(), sizeof(double) * frames.size());
  if (!extrinsics.empty())
    std::memcpy(extrinsics.data(), problem.extrinsics.data(), sizeof(double) * extrinsics.size());
  std::memcpy(pool.data(), problem.pool.data(), sizeof(double) * pool.size());
  std::vector<int32_t> indices;  // iframe, icam_intrinsics, icam_extrinsics per observation
  for (const mrcal_observation_board_t& observation : problem.observations) {
    indices.insert(indices.end(),
                   {observation.iframe, observation.icam.intrinsics, observation.icam.extrinsics});
  }
  const mrcal_problem_selections_t& selections = problem.selections;
  const std::vector<std::pair<std::string, std::string>> members = {
      {"intrinsics",
       NpyDoubles(problem.intrinsics, fmt::format("({}, {})", problem.cameras, per_camera))},
      {"extrinsics_rt_fromref",
       extrinsics.empty()
           ? NpyString("")
           : NpyDoubles(extrinsics, fmt::format("({}, 6)", problem.Extrinsics()))},
      {"frames_rt_toref", NpyDoubles(frames, fmt::format("({}, 6)", views))},
      {"points", NpyString("")},
      {"observations_board",
       NpyDoubles(pool, fmt::format("({}, {}, {}, 3)", observation_count, problem.corners_y,
                                    problem.corners_x))},
      {"indices_frame_camintrinsics_camextrinsics",
       NpyInts(indices, fmt::format("({}, 3)", observation_count))},
      {"observations_point", NpyString("")},
      {"indices_point_camintrinsics_camextrinsics", NpyString("")},
      {"lensmodel", NpyString(lens_model)},
      {"imagersizes", NpyInts(std::vector<int32_t>(problem.imager_sizes.begin(),
                                                   problem.imager_sizes.end()),
                              fmt::format("({}, 2)", problem.cameras))},
      {"calobject_warp", NpyString("")},
      {"Npoints_fixed", NpyInt64(0)},
      {"do_optimize_intrinsics_core", NpyBool(selections.do_optimize_intrinsics_core)},
      {"do_optimize_intrinsics_distortions",
       NpyBool(selections.do_optimize_intrinsics_distortions)},
      {"do_optimize_extrinsics", NpyBool(selections.do_optimize_extrinsics)},
      {"do_optimize_frames", NpyBool(selections.do_optimize_frames)},
      {"do_optimize_calobject_warp", NpyBool(selections.do_optimize_calobject_warp)},
      {"calibration_object_spacing", NpyDouble(problem.spacing)},
      {"point_min_range", NpyDouble(kChessboardConstants.point_min_range)},
      {"point_max_range", NpyDouble(kChessboardConstants.point_max_range)},
      {"verbose", NpyBool(false)},
      {"do_apply_regularization", NpyBool(selections.do_apply_regularization)},
      {"do_apply_outlier_rejection", NpyBool(selections.do_apply_outlier_rejection)},
  };
  std::vector<std::pair<std::string, std::string>> files;
  for (const auto& [key, npy] : members) files.emplace_back(key + ".npy", npy);
  return Base85(Zip(files));
}

}  // namespace procam
