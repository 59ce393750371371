// The camera readers: mrcal .cameramodel (through libmrcal), OpenCV FileStorage YAML,
// the content sniffing of CameraModel::Read, and the rig YAML (inline cameras, or
// `model:` files relative to the rig file), and the chessboard problem in a
// .cameramodel's optimization_inputs (base85, zip, deflate, .npy; the lens audit's input).
#include "calib/mrcal_optimization_inputs.h"
#include "fuzz/fuzz_support.h"
#include "fuzz/fuzz_targets.h"
#include "vision/camera_model.h"

namespace mcms::fuzz {

namespace {
// A model that was read must be usable: project a point in front of it.
void Use(const CameraModel& m) { (void)m.Project(Vec3(0.01, -0.02, 1.0)); }
}  // namespace

int FuzzCamera(const uint8_t* data, size_t size) {
  const auto cameramodel = WriteInput(data, size, ".cameramodel");
  ExpectInputError(cameramodel.string(), [&] { Use(CameraModel::ReadCameramodel(cameramodel)); });
  ExpectInputError(cameramodel.string(), [&] { Use(CameraModel::Read(cameramodel)); });
  ExpectInputError(cameramodel.string(), [&] { (void)ReadMrcalOptimizationInputs(cameramodel); });
  const auto yaml = WriteInput(data, size, ".yaml");
  ExpectInputError(yaml.string(), [&] { Use(CameraModel::ReadOpenCvYaml(yaml)); });
  ExpectInputError(yaml.string(), [&] {
    const CameraRig rig = CameraRig::Read(yaml);
    for (const auto& c : rig.cameras) Use(c);
  });
  return 0;
}

}  // namespace mcms::fuzz
